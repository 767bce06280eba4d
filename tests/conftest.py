"""Shared fixtures. GL contexts for tests are created here and nowhere else."""
from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture(scope="session")
def gl_session():
    """The one headless context of the test session (skips where none can be made)."""
    from ffls.errors import GLUnavailable
    from ffls.gpu.context import create_headless_context

    try:
        ctx = create_headless_context()
    except GLUnavailable as e:
        pytest.skip(f"no headless OpenGL 4.3 context: {e}")
    yield ctx
    ctx.release()


@pytest.fixture
def ctx(gl_session):
    """The session's headless context, made current (a viewer window may have been); asserts no
    GL error before and after each test."""
    from ffls.gpu.context import make_current

    make_current(gl_session)
    assert gl_session.error == "GL_NO_ERROR"
    yield gl_session
    gl_session.gc()
    err = gl_session.error
    assert err == "GL_NO_ERROR", f"GL error after test: {err}"


@pytest.fixture
def rng():
    return np.random.default_rng(20021)
