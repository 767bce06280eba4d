#!/usr/bin/env bash
# Set up ffls on a fresh Debian machine (run as root for the system packages):
# system libraries for headless OpenGL (Mesa EGL/llvmpipe, OSMesa), Xvfb and ffmpeg,
# then a virtual environment in .venv with ffls installed (editable) and its test extras.
set -euo pipefail
cd "$(dirname "$0")/.."

PKGS=(python3 python3-venv python3-pip libegl1 libgl1 libosmesa6 xvfb ffmpeg)
missing=()
for p in "${PKGS[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  if [ "$(id -u)" -ne 0 ]; then
    echo "setup: missing system packages: ${missing[*]} (run as root, or: sudo apt-get install ${missing[*]})" >&2
    exit 1
  fi
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  "$PY" -m venv .venv
fi
.venv/bin/python -m pip install -q --upgrade pip >/dev/null
.venv/bin/python -m pip install -q -e '.[test]'
# an editable install compiles nothing: where PYTHONDONTWRITEBYTECODE is set, every run compiled
# ffls again (the main process's CPU of `ffls lights` 0.93x with it compiled; docs/spheres.md, Speed)
.venv/bin/python -m compileall -q ffls >/dev/null
echo "setup: ffls installed in $(pwd)/.venv"
