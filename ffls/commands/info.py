"""``ffls info``: what the headless OpenGL factory finds (backend, renderer, version, limits)."""
from __future__ import annotations

import json

NAME = "info"
HELP = "show the headless OpenGL context ffls gets: backend, renderer, GL version and limits"
DESCRIPTION = (
    "Create a headless OpenGL context the way every ffls command does (EGL, then OSMesa; "
    "FFLS_GL_BACKEND or --backend forces one) and print its backend, renderer, GL version and "
    "the limits ffls depends on: texture size, array layers, SSBO size, compute limits, float "
    "atomics, float64 in shaders."
)

_LABELS = (
    ("backend", "backend"),
    ("renderer", "renderer"),
    ("vendor", "vendor"),
    ("version", "GL version"),
    ("gl_version_code", "GL version code"),
    ("max_texture_size", "max texture size"),
    ("max_array_texture_layers", "max array texture layers"),
    ("max_ssbo_bytes", "max SSBO block bytes"),
    ("max_ssbo_bindings", "max SSBO bindings"),
    ("max_compute_work_group_invocations", "max compute invocations"),
    ("max_compute_work_group_size", "max compute work-group size"),
    ("max_compute_work_group_count", "max compute work-group count"),
    ("max_viewport_dims", "max viewport"),
    ("float_atomics", "float atomics (NV)"),
    ("fp64", "float64 in shaders"),
)


def add_arguments(p):
    p.add_argument("--backend", choices=("egl", "osmesa"), default=None,
                   help="force a backend (default: EGL, then OSMesa; FFLS_GL_BACKEND also works)")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")


def format_info(info: dict) -> str:
    """The table ``ffls info`` prints, one ``label: value`` line per entry of :func:`describe_context`."""
    width = max(len(label) for _, label in _LABELS)
    lines = []
    for key, label in _LABELS:
        v = info.get(key)
        if isinstance(v, (list, tuple)):
            v = " x ".join(str(x) for x in v)
        elif isinstance(v, bool):
            v = "yes" if v else "no"
        lines.append(f"{label:<{width}} : {'?' if v is None else v}")
    return "\n".join(lines)


def gather(backend: str | None = None) -> dict:
    """Create a headless context (``backend`` or the factory's order), describe it, release it.

    Raises
    ------
    ffls.errors.GLUnavailable
        If no backend gives OpenGL 4.3.
    """
    import os

    from ffls.gpu.context import create_headless_context, describe_context

    ctx = create_headless_context(backend=backend)
    try:
        info = describe_context(ctx)
    finally:
        ctx.release()
    info["cpu_count"] = os.cpu_count()
    return info


def run(args) -> int:
    info = gather(args.backend)
    print(json.dumps(info, indent=2) if args.json else format_info(info))
    return 0
