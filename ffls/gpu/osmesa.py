"""OSMesa: an off-screen Mesa context, the fallback of the headless factory.

glcontext (moderngl's platform layer) ships only EGL and X11 backends on Linux, but
``moderngl.create_context`` accepts ``context=`` any object following glcontext's context
protocol: ``load_opengl_function(name) -> int`` (a function address, 0 when missing),
``release()``, and ``__enter__`` / ``__exit__`` (make current / restore). :class:`OSMesaContext`
implements that protocol with :mod:`ctypes` over ``libOSMesa.so.8`` (Debian/Ubuntu package
``libosmesa6``, Mesa >= 20 gallium/llvmpipe):

1. ``OSMesaCreateContextAttribs`` with ``OSMESA_PROFILE = OSMESA_CORE_PROFILE`` and the
   highest core version the library accepts (4.6 down to the required one);
2. ``OSMesaMakeCurrent`` with a small private RGBA8 colour buffer (ffls renders only into its own
   framebuffer objects; the default framebuffer is never used);
3. ``OSMesaGetProcAddress`` for every GL entry point moderngl loads.

Only the factory in :mod:`ffls.gpu.context` calls :func:`create_osmesa_context`.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import os

from ffls.errors import GLUnavailable

__all__ = ["OSMesaContext", "create_osmesa_context", "find_osmesa_library"]

# GL/osmesa.h
OSMESA_RGBA = 0x1908
OSMESA_FORMAT = 0x22
OSMESA_DEPTH_BITS = 0x30
OSMESA_STENCIL_BITS = 0x31
OSMESA_ACCUM_BITS = 0x32
OSMESA_PROFILE = 0x33
OSMESA_CORE_PROFILE = 0x34
OSMESA_CONTEXT_MAJOR_VERSION = 0x36
OSMESA_CONTEXT_MINOR_VERSION = 0x37
GL_UNSIGNED_BYTE = 0x1401

_CANDIDATE_NAMES = ("libOSMesa.so.8", "libOSMesa.so.6", "libOSMesa.so")
_BUFFER_SIDE = 16  # the private colour buffer (pixels per side)


def find_osmesa_library() -> str | None:
    """Name or path of the OSMesa shared library, or ``None``.

    ``FFLS_OSMESA_LIBRARY`` (a path) wins; then ``libOSMesa.so.8`` and the names
    :func:`ctypes.util.find_library` knows.
    """
    env = os.environ.get("FFLS_OSMESA_LIBRARY")
    if env:
        return env
    for name in _CANDIDATE_NAMES:
        try:
            ctypes.CDLL(name)
            return name
        except OSError:
            continue
    return ctypes.util.find_library("OSMesa")


def _load(libname: str):
    lib = ctypes.CDLL(libname)
    lib.OSMesaCreateContextAttribs.restype = ctypes.c_void_p
    lib.OSMesaCreateContextAttribs.argtypes = [ctypes.POINTER(ctypes.c_int), ctypes.c_void_p]
    lib.OSMesaMakeCurrent.restype = ctypes.c_ubyte
    lib.OSMesaMakeCurrent.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_uint, ctypes.c_int, ctypes.c_int]
    lib.OSMesaGetProcAddress.restype = ctypes.c_void_p
    lib.OSMesaGetProcAddress.argtypes = [ctypes.c_char_p]
    lib.OSMesaGetCurrentContext.restype = ctypes.c_void_p
    lib.OSMesaGetCurrentContext.argtypes = []
    lib.OSMesaDestroyContext.restype = None
    lib.OSMesaDestroyContext.argtypes = [ctypes.c_void_p]
    return lib


class OSMesaContext:
    """An OSMesa core-profile context in glcontext's context protocol.

    Parameters
    ----------
    require : int
        Minimum OpenGL version, ``major * 100 + minor * 10`` (e.g. 430).
    libname : str, optional
        The OSMesa library (default: :func:`find_osmesa_library`).

    Raises
    ------
    GLUnavailable
        The library is missing, lacks ``OSMesaCreateContextAttribs`` (OSMesa older than Mesa
        11.2, or the classic swrast build, which has no core profile), or no core context of at
        least ``require`` could be created or made current.
    """

    def __init__(self, require: int = 430, libname: str | None = None):
        libname = libname or find_osmesa_library()
        if not libname:
            raise GLUnavailable("osmesa: libOSMesa not found (apt-get install libosmesa6, "
                                "or set FFLS_OSMESA_LIBRARY to its path)")
        try:
            self._lib = _load(libname)
        except OSError as e:
            raise GLUnavailable(f"osmesa: cannot load {libname}: {e}") from None
        except AttributeError as e:
            raise GLUnavailable(f"osmesa: {libname} has no core-profile entry points ({e}); "
                                "it needs Mesa >= 11.2 built with gallium OSMesa") from None
        self.libname = libname
        self._ctx = None
        self.version = None
        tried = []
        want_major, want_minor = require // 100, require % 100 // 10
        for major, minor in ((4, 6), (4, 5), (4, 4), (4, 3), (4, 2), (4, 1), (4, 0), (3, 3)):
            if (major, minor) < (want_major, want_minor):
                break
            attrs = (ctypes.c_int * 15)(
                OSMESA_FORMAT, OSMESA_RGBA, OSMESA_DEPTH_BITS, 24, OSMESA_STENCIL_BITS, 8,
                OSMESA_ACCUM_BITS, 0, OSMESA_PROFILE, OSMESA_CORE_PROFILE,
                OSMESA_CONTEXT_MAJOR_VERSION, major, OSMESA_CONTEXT_MINOR_VERSION, minor, 0)
            ctx = self._lib.OSMesaCreateContextAttribs(attrs, None)
            if ctx:
                self._ctx = ctx
                self.version = major * 100 + minor * 10
                break
            tried.append(f"{major}.{minor}")
        if not self._ctx:
            raise GLUnavailable(f"osmesa: {libname} refused a core-profile context of version "
                                f"{', '.join(tried) or 'none'} (need {want_major}.{want_minor}; OSMesa offers at most 4.6)")
        self._buffer = ctypes.create_string_buffer(4 * _BUFFER_SIDE * _BUFFER_SIDE)
        self._previous: list = []
        if not self._make_current():
            self.release()
            raise GLUnavailable(f"osmesa: OSMesaMakeCurrent failed ({libname})")

    def _make_current(self) -> bool:
        return bool(self._lib.OSMesaMakeCurrent(self._ctx, self._buffer, GL_UNSIGNED_BYTE,
                                                _BUFFER_SIDE, _BUFFER_SIDE))

    # glcontext protocol ------------------------------------------------------------------
    def load_opengl_function(self, name: str) -> int:
        """Address of GL entry point ``name`` (0 if OSMesa does not know it)."""
        return self._lib.OSMesaGetProcAddress(name.encode("ascii")) or 0

    def __enter__(self):
        self._previous.append(self._lib.OSMesaGetCurrentContext())
        self._make_current()
        return self

    def __exit__(self, *exc):
        prev = self._previous.pop() if self._previous else None
        if prev and prev != self._ctx:
            # an OSMesa context made current by someone else: we cannot know its buffer, so
            # leave ours current (OSMesa offers no way to query the previous buffer)
            pass

    def release(self) -> None:
        """Destroy the OSMesa context (idempotent)."""
        if self._ctx:
            self._lib.OSMesaDestroyContext(self._ctx)
            self._ctx = None


def create_osmesa_context(require: int = 430):
    """A standalone ``moderngl.Context`` on OSMesa with OpenGL ``require`` or newer (core).

    Parameters
    ----------
    require : int
        Minimum OpenGL version as ``major * 100 + minor * 10``.

    Returns
    -------
    moderngl.Context
        Standalone (no default framebuffer); ``ctx.release()`` destroys the OSMesa context.

    Raises
    ------
    GLUnavailable
        See :class:`OSMesaContext`; also when moderngl reports a lower version than required.
    """
    import moderngl

    loader = OSMesaContext(require)
    try:
        ctx = moderngl.create_context(standalone=True, require=require, context=loader)
    except Exception as e:  # moderngl raises plain Exception / ValueError
        loader.release()
        raise GLUnavailable(f"osmesa: moderngl could not use the OSMesa context: {' '.join(str(e).split())}") from None
    ctx.extra = {"backend": "osmesa", "osmesa_library": loader.libname}
    return ctx
