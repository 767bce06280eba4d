"""The one shader loader of ffls.

Shaders live in the ``shaders/`` folder of the source tree, installed as the package
``ffls.shaders``; they are found from the package location, never from the working directory.
One file holds one program; its stages are chosen with ``#if defined VERTEX_SHADER``,
``FRAGMENT_SHADER``, ``GEOMETRY_SHADER`` or ``COMPUTE_SHADER``. Shared code is pulled in with
``#include "name.glsl"`` from ``shaders/include/``.

Driver errors keep the files' own line numbers: every chunk of source is preceded by a ``#line``
directive whose source-string number is mapped back to a file name in the error message.
"""
from __future__ import annotations

import re
import weakref
from pathlib import Path

from ffls.errors import FflsError

GLSL_VERSION = "#version 430 core"
_STAGES = ("VERTEX_SHADER", "GEOMETRY_SHADER", "FRAGMENT_SHADER", "COMPUTE_SHADER")
_INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"\s*$')


def shader_dir() -> Path:
    """The folder holding the ``.glsl`` files (from the installed package)."""
    from ffls.shaders import SHADER_DIR

    return SHADER_DIR


class ShaderError(FflsError):
    """A GLSL compile or link error, with file names and line numbers of the sources."""


def _read(name: str) -> tuple[Path, str]:
    root = shader_dir()
    if Path(name).is_absolute():  # a program outside the package (a test's probe); includes still come from root
        cands = (Path(name),)
    else:
        cands = (root / name, root / "include" / name)
    for cand in cands:
        if cand.is_file():
            return cand, cand.read_text()
    raise ShaderError(f"no shader file {name!r} in {root}")


def preprocess(name: str, stage: str, defines: dict | None = None) -> tuple[str, list[Path]]:
    """Expand a program file for one stage.

    Returns the source and the list of files, indexed by the GLSL source-string number that the
    ``#line`` directives use (0 is the program file itself).
    """
    path, text = _read(name)
    files: list[Path] = [path]
    head = [GLSL_VERSION, f"#define {stage}"]
    for k, v in sorted((defines or {}).items()):
        head.append(f"#define {k} {'' if v is None or v is True else v}".rstrip())
    out = head + ["#line 1 0"]

    def expand(src: str, file_no: int, stack: tuple[str, ...]):
        for i, line in enumerate(src.splitlines(), start=1):
            m = _INCLUDE.match(line)
            if not m:
                out.append(line)
                continue
            inc = m.group(1)
            if inc in stack:
                raise ShaderError(f"recursive #include of {inc!r}", files[file_no])
            inc_path, inc_text = _read(inc)
            if inc_path in files:  # included once per program: acts as an include guard
                out.append("")
                continue
            files.append(inc_path)
            out.append(f"#line 1 {len(files) - 1}")
            expand(inc_text, len(files) - 1, stack + (inc,))
            out.append(f"#line {i + 1} {file_no}")

    expand(text, 0, (name,))
    return "\n".join(out) + "\n", files


def _stages_in(name: str) -> list[str]:
    _, text = _read(name)
    return [s for s in _STAGES if re.search(rf"defined\s*\(?\s*{s}\b", text)]


def _annotate(msg: str, files: list[Path]) -> str:
    def repl(m):
        k = int(m.group(1))
        fname = files[k].name if k < len(files) else f"source {k}"
        return f"{fname}:{m.group(2)}"

    # Mesa writes "0:12(3): error", NVIDIA "0(12) : error"
    msg = re.sub(r"\b(\d+):(\d+)\(\d+\)", repl, msg)
    return re.sub(r"\b(\d+)\((\d+)\)", repl, msg)


_cache: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def load_program(ctx, name: str, defines: dict | None = None, varyings: tuple[str, ...] = ()):
    """Compile (or fetch from the cache) the program in ``shaders/<name>``.

    ``name`` may also be the absolute path of a program file outside the package (the tests'
    probe programs in ``tests/shaders/``); its ``#include`` files still come from ``shaders/``.

    Programs are cached by (context, name, defines) and released together by
    :func:`release_programs`. A file with a ``COMPUTE_SHADER`` section gives a
    ``moderngl.ComputeShader``; otherwise a ``moderngl.Program`` from the stages it defines.
    """
    import moderngl

    key = (name, tuple(sorted((defines or {}).items())), tuple(varyings))
    per_ctx = _cache.setdefault(ctx, {})
    if key in per_ctx:
        return per_ctx[key]
    stages = _stages_in(name)
    if not stages:
        raise ShaderError(f"{name} defines no stage (#if defined VERTEX_SHADER ...)")
    files: list[Path] = []
    try:
        if "COMPUTE_SHADER" in stages:
            src, files = preprocess(name, "COMPUTE_SHADER", defines)
            prog = ctx.compute_shader(src)
        else:
            kw = {}
            for stage, arg in (("VERTEX_SHADER", "vertex_shader"), ("GEOMETRY_SHADER", "geometry_shader"),
                               ("FRAGMENT_SHADER", "fragment_shader")):
                if stage in stages:
                    kw[arg], files = preprocess(name, stage, defines)
            if varyings:
                kw["varyings"] = varyings
            prog = ctx.program(**kw)
    except moderngl.Error as e:
        raise ShaderError(f"{name}: {_annotate(str(e), files or [shader_dir() / name])}") from None
    per_ctx[key] = prog
    return prog


def release_programs(ctx) -> None:
    """Release every cached program of ``ctx``."""
    for prog in _cache.pop(ctx, {}).values():
        prog.release()
