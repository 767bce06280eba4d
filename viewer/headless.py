"""The window platform of the viewer: a desktop (X11/Wayland) window, or glfw's null platform.

glfw 3.4's *null* platform makes windows that exist only in memory; with EGL as the context
creation API (Mesa's surfaceless EGL, llvmpipe or a GPU) it renders the whole viewer, imgui
included, into a default framebuffer that can be read back. No X server is needed: this is
what ``ffls view --frames N --screenshot OUT.png`` uses on a machine with no display and what
the tests use.

The null platform is chosen when asked (``--headless``) or when neither ``DISPLAY`` nor
``WAYLAND_DISPLAY`` is set; it never silently needs an X display.
"""
from __future__ import annotations

import os

from ffls.errors import GLUnavailable

__all__ = ["has_display", "choose_platform", "init_glfw", "window_hints"]


def has_display(environ=None) -> bool:
    """Whether a desktop session is reachable (``DISPLAY`` or ``WAYLAND_DISPLAY`` set)."""
    env = os.environ if environ is None else environ
    return bool(env.get("DISPLAY") or env.get("WAYLAND_DISPLAY"))


def choose_platform(headless: bool | None = None, environ=None) -> str:
    """``'null'`` (glfw's null platform + EGL) or ``'desktop'``.

    Parameters
    ----------
    headless : bool, optional
        True forces the null platform, False forces a desktop window; None chooses the null
        platform when :func:`has_display` is False.
    """
    if headless is None:
        return "desktop" if has_display(environ) else "null"
    return "null" if headless else "desktop"


def _import_glfw():
    import imgui_bundle  # noqa: F401  (first: points pyglfw at imgui-bundle's own GLFW 3.4)
    import glfw

    return glfw


def init_glfw(platform: str):
    """Initialise glfw for ``platform`` and return the ``glfw`` module.

    Raises
    ------
    ffls.errors.GLUnavailable
        glfw cannot start (no display for a desktop window, or no null platform).
    """
    glfw = _import_glfw()
    errors = []
    glfw.set_error_callback(lambda code, msg: errors.append(msg.decode() if isinstance(msg, bytes) else str(msg)))
    if platform == "null":
        glfw.init_hint(glfw.PLATFORM, glfw.PLATFORM_NULL)
    else:
        glfw.init_hint(glfw.PLATFORM, glfw.ANY_PLATFORM)
    if not glfw.init():
        why = "; ".join(errors) or "unknown reason"
        hint = "" if platform == "null" else " (no display? use --headless)"
        raise GLUnavailable(f"glfw could not initialise the {platform} platform: {why}{hint}")
    glfw.set_error_callback(None)
    return glfw


def window_hints(glfw, platform: str, visible: bool = True) -> None:
    """Ask for an OpenGL 4.3 core context (EGL on the null platform)."""
    glfw.default_window_hints()
    glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, 4)
    glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, 3)
    glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
    glfw.window_hint(glfw.OPENGL_FORWARD_COMPAT, True)
    glfw.window_hint(glfw.SCALE_TO_MONITOR, True)
    glfw.window_hint(glfw.VISIBLE, bool(visible))
    if platform == "null":
        glfw.window_hint(glfw.CONTEXT_CREATION_API, glfw.EGL_CONTEXT_API)


_glfw_users = 0


def acquire_glfw(platform: str):
    """:func:`init_glfw` counted: several viewer windows may share one glfw initialisation."""
    global _glfw_users
    glfw = init_glfw(platform) if _glfw_users == 0 else _import_glfw()
    _glfw_users += 1
    return glfw


def release_glfw(glfw) -> None:
    """Undo one :func:`acquire_glfw`; the last one terminates glfw."""
    global _glfw_users
    _glfw_users = max(0, _glfw_users - 1)
    if _glfw_users == 0:
        glfw.terminate()


class CurrentEGLContext:
    """Remembers the EGL context current on this thread and makes it current again later.

    The viewer makes its window's context current; a caller that had a headless EGL context
    current (:func:`ffls.gpu.context.create_headless_context`, e.g. the demo or a test session)
    gets it back when the viewer closes. A no-op where libEGL cannot be loaded or nothing was
    current.
    """

    def __init__(self):
        self._egl = None
        self._saved = None
        try:
            import ctypes
            import ctypes.util

            egl = ctypes.CDLL(ctypes.util.find_library("EGL") or "libEGL.so.1")
            for name in ("eglGetCurrentContext", "eglGetCurrentDisplay", "eglGetCurrentSurface"):
                getattr(egl, name).restype = ctypes.c_void_p
            egl.eglGetCurrentSurface.argtypes = [ctypes.c_int]
            egl.eglMakeCurrent.argtypes = [ctypes.c_void_p] * 4
            egl.eglMakeCurrent.restype = ctypes.c_uint
            self._egl = egl
        except (OSError, AttributeError):
            return
        ctx = egl.eglGetCurrentContext()
        if ctx:
            self._saved = (egl.eglGetCurrentDisplay(), egl.eglGetCurrentSurface(0x3059),  # EGL_DRAW
                           egl.eglGetCurrentSurface(0x305A), ctx)  # EGL_READ

    def restore(self) -> bool:
        """Make the remembered context current again; True when there was one."""
        if self._egl is None or self._saved is None:
            return False
        dpy, draw, read, ctx = self._saved
        return bool(self._egl.eglMakeCurrent(dpy, draw, read, ctx))
