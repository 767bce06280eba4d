"""Shared fixtures. GL contexts for tests are created here and nowhere else."""
from __future__ import annotations

import shutil
import subprocess
import tempfile
from pathlib import Path

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


@pytest.fixture(scope="session")
def courtyard_ball_folder(tmp_path_factory):
    """A diffuse probe folder: a 48 px ball of albedo 0.7 under the courtyard map (cut to 16 rows),
    read by the ``ffls probe pocs`` CLI tests (never written into)."""
    from ffls.lightmaps.lightmap import builtin_lightmap
    from ffls.synth.probe_scenes import diffuse_sphere_scene, write_diffuse_probe

    sc = diffuse_sphere_scene(builtin_lightmap("courtyard").downsample(16), resolution=48, albedo=0.7)
    return write_diffuse_probe(tmp_path_factory.mktemp("courtyard_ball"), sc)


@pytest.fixture
def tiny_tmpfs():
    """A 64 kB tmpfs (needs root and mount); skipped where it cannot be mounted."""
    d = Path(tempfile.mkdtemp(prefix="ffls-tmpfs-"))
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(d)], capture_output=True)
    if r.returncode != 0:
        d.rmdir()
        pytest.skip("cannot mount a tmpfs here (needs root)")
    try:
        yield d
    finally:
        subprocess.run(["umount", str(d)], capture_output=True)
        shutil.rmtree(d, ignore_errors=True)
