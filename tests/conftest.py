"""Shared fixtures. GL contexts for tests are created here and nowhere else."""
from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture(scope="session")
def _gl_context():
    from ffls.errors import GLUnavailable
    from ffls.gpu.context import create_headless_context

    try:
        ctx = create_headless_context()
    except GLUnavailable as e:
        pytest.skip(f"no headless OpenGL 4.3 context: {e}")
    yield ctx
    ctx.release()


@pytest.fixture
def ctx(_gl_context):
    """The session's headless context; asserts no GL error before and after each test."""
    assert _gl_context.error == "GL_NO_ERROR"
    yield _gl_context
    _gl_context.gc()
    err = _gl_context.error
    assert err == "GL_NO_ERROR", f"GL error after test: {err}"


@pytest.fixture
def rng():
    return np.random.default_rng(20021)
