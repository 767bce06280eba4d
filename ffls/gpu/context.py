"""Headless OpenGL contexts: EGL first, OSMesa as the fallback.

This is one of the two places in ffls that create contexts (the other is the viewer's window).
The library itself only ever receives a ``moderngl.Context``.
"""
from __future__ import annotations

import os

from ffls.errors import GLUnavailable

REQUIRED_GL = 430  # compute shaders and SSBOs


def create_headless_context(backend: str | None = None, require: int = REQUIRED_GL):
    """Create a standalone ``moderngl.Context`` without any window system.

    Parameters
    ----------
    backend : {'egl', 'osmesa', None}
        ``None`` tries EGL (a GPU where there is one, Mesa llvmpipe otherwise), then OSMesa.
        The environment variable ``FFLS_GL_BACKEND`` overrides it.
    require : int
        Minimum OpenGL version as ``major * 100 + minor * 10``.

    Raises
    ------
    GLUnavailable
        If no backend gives an OpenGL ``require`` context; the message lists what each said.
    """
    import moderngl

    backend = backend or os.environ.get("FFLS_GL_BACKEND") or None
    order = [backend] if backend else ["egl", "osmesa"]
    failures = []
    for name in order:
        try:
            if name == "osmesa":
                ctx = _create_osmesa(require)
            else:
                ctx = moderngl.create_context(standalone=True, backend=name, require=require)
            # GL objects are released when Python drops them, or earlier by an explicit
            # release(). ("context_gc" would be the alternative, but moderngl 5.13 queues
            # explicitly released objects again and ctx.gc() then fails.)
            ctx.gc_mode = "auto"
            if not isinstance(ctx.extra, dict):
                ctx.extra = {}
            ctx.extra.setdefault("backend", name)
            return ctx
        except Exception as e:  # moderngl raises plain Exception for missing libraries
            failures.append(f"{name}: {' '.join(str(e).split())}")
    raise GLUnavailable(
        f"no OpenGL {require // 100}.{require % 100 // 10} context: " + "; ".join(failures)
        + " (install Mesa: apt-get install libegl1 libgl1 libosmesa6)"
    )


def _create_osmesa(require: int):
    """An OSMesa context (glcontext ships no OSMesa backend; see ffls.gpu.osmesa)."""
    from ffls.gpu.osmesa import create_osmesa_context

    return create_osmesa_context(require)


#: GL_RENDERER substrings of CPU rasterisers (Mesa llvmpipe/softpipe/swrast, SwiftShader).
SOFTWARE_RENDERERS = ("llvmpipe", "softpipe", "swrast", "swiftshader")


def is_software_renderer(renderer: str) -> bool:
    """True when ``renderer`` (a GL_RENDERER string) names a CPU rasteriser."""
    r = (renderer or "").lower()
    return any(s in r for s in SOFTWARE_RENDERERS)


def describe_context(ctx) -> dict:
    """What a context offers: backend, renderer, version, and the limits ffls depends on.

    Returns
    -------
    dict
        JSON-serialisable: strings, ints, bools and lists of ints.
    """
    info = ctx.info

    def lim(name):
        v = info.get(name)
        return list(v) if isinstance(v, tuple) else v

    extra = ctx.extra if isinstance(ctx.extra, dict) else {}
    return {
        "backend": extra.get("backend"),
        "vendor": info.get("GL_VENDOR"),
        "renderer": info.get("GL_RENDERER"),
        "version": info.get("GL_VERSION"),
        "glsl": info.get("GL_SHADING_LANGUAGE_VERSION"),
        "gl_version_code": ctx.version_code,
        "max_texture_size": info.get("GL_MAX_TEXTURE_SIZE"),
        "max_array_texture_layers": info.get("GL_MAX_ARRAY_TEXTURE_LAYERS"),
        "max_ssbo_bytes": info.get("GL_MAX_SHADER_STORAGE_BLOCK_SIZE"),
        "max_compute_work_group_invocations": info.get("GL_MAX_COMPUTE_WORK_GROUP_INVOCATIONS"),
        "max_compute_work_group_count": lim("GL_MAX_COMPUTE_WORK_GROUP_COUNT"),
        "max_compute_work_group_size": lim("GL_MAX_COMPUTE_WORK_GROUP_SIZE"),
        "max_ssbo_bindings": info.get("GL_MAX_SHADER_STORAGE_BUFFER_BINDINGS"),
        "max_viewport_dims": lim("GL_MAX_VIEWPORT_DIMS"),
        "float_atomics": "GL_NV_shader_atomic_float" in ctx.extensions,
        "fp64": ctx.version_code >= 400 or "GL_ARB_gpu_shader_fp64" in ctx.extensions,
    }


def release_gl(obj) -> None:
    """Release a moderngl object now; None is ignored.

    Contexts made here run ``gc_mode='auto'``, so an object released explicitly may also be
    dropped by Python later without harm.
    """
    if obj is not None:
        obj.release()


def default_framebuffer(ctx):
    """Framebuffer 0 of ``ctx``, as a moderngl reference (never deleted by garbage collection).

    Passes that draw into their own framebuffer bind this one afterwards when none was bound
    before: moderngl re-binds the bound framebuffer whenever it creates one, which fails once a
    pass's framebuffer is released. A new reference is cheap (no GL object is made), so none is
    cached.
    """
    return ctx.detect_framebuffer(0)


def make_current(ctx) -> None:
    """Make ``ctx`` current on this thread (after another context, e.g. a viewer window's, was).

    moderngl makes a context current on entering ``with ctx:`` and restores the previous one on
    leaving; this is the entry alone, for a caller that keeps ``ctx`` current from now on.
    """
    ctx.__enter__()
