"""The built-in demo: synthesise a capture, relight it under the built-in light maps at several
rotations, and write the images and a contact sheet.

Everything here is a library call that :mod:`ffls.commands.demo` wraps; tests call
:func:`run_demo` directly.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from ffls.display.tonemap import auto_exposure  # noqa: F401  (moved to ffls.display.tonemap; kept importable here)
from ffls.radiance.photos import load_photos

DEFAULT_MAPS = ("courtyard", "studio", "sunrise", "night", "sky", "paper")
DEFAULT_ROTATIONS = (0.0, 90.0, 180.0, 270.0)


@dataclass
class DemoResult:
    """Where the demo wrote its files, and how it rendered them."""

    out_dir: Path
    capture_dir: Path
    images: dict = field(default_factory=dict)  # (map name, rotation) -> PNG path
    exrs: dict = field(default_factory=dict)  # (map name, rotation) -> EXR path
    contact_sheet: Path | None = None
    backend: str = "cpu"  # 'gpu: <renderer>' or 'cpu'
    seconds: dict = field(default_factory=dict)


def _relighter(capture, lights, use_gpu):
    """Return (render(lightmap, rotation) -> HDR image (H, W, 3) float32, backend description, release)."""
    from ffls.conventions import rotation_z

    if use_gpu in ("auto", True):
        try:
            from ffls.errors import GLUnavailable
            from ffls.gpu.context import create_headless_context
            from ffls.gpu.engine import Engine

            ctx = create_headless_context()
        except (GLUnavailable, ImportError) as e:
            if use_gpu is True:
                raise
            print(f"ffls demo: no GPU path ({e}); using the CPU reference relighter")
        else:
            engine = Engine.from_capture(ctx, capture, lights)

            def render(lm, deg):
                engine.set_lightmap(lm)
                engine.set_rotation(rotation_z(deg))
                engine.render()
                return engine.read_hdr()

            def release():
                engine.release()
                ctx.release()

            return render, f"gpu: {ctx.info['GL_RENDERER']}", release

    from ffls.relight.cpu import relight_fast
    from ffls.weights.voronoi import bake_cells, integrate_weights

    idx = np.flatnonzero(lights.ok_mask)
    dirs = lights.directions[idx]
    basis = load_photos(capture, idx)
    cells = bake_cells(dirs, capture.hemisphere)

    def render(lm, deg):
        w = integrate_weights(lm, dirs, rotation_z(deg), capture.hemisphere, cells=cells)
        return relight_fast(w.weights, basis)

    return render, "cpu", lambda: None


def contact_sheet(tiles: list[list[np.ndarray]], row_labels, col_labels, path) -> Path:
    """Write a grid of uint8 (H, W, 3) tiles with labels to a PNG (atomically)."""
    from PIL import Image, ImageDraw

    from ffls.errors import atomic_output

    h, w = tiles[0][0].shape[:2]
    pad, top, left = 4, 22, 90
    rows, cols = len(tiles), len(tiles[0])
    sheet = Image.new("RGB", (left + cols * (w + pad), top + rows * (h + pad)), (24, 24, 24))
    draw = ImageDraw.Draw(sheet)
    for c, label in enumerate(col_labels):
        draw.text((left + c * (w + pad) + 4, 5), label, fill=(230, 230, 230))
    for r, label in enumerate(row_labels):
        draw.text((6, top + r * (h + pad) + h // 2 - 6), label, fill=(230, 230, 230))
        for c in range(cols):
            sheet.paste(Image.fromarray(tiles[r][c]), (left + c * (w + pad), top + r * (h + pad)))
    path = Path(path)
    with atomic_output(path) as tmp:
        sheet.save(tmp, format="PNG")
    return path


def run_demo(out_dir="ffls-demo", n_lights: int = 160, resolution: int = 256, maps=DEFAULT_MAPS,
             rotations=DEFAULT_ROTATIONS, use_gpu="auto", seed: int = 0, progress: bool = True) -> DemoResult:
    """Synthesise a capture and relight it under ``maps`` at each of ``rotations`` (degrees about +Z).

    Parameters
    ----------
    out_dir : path
        Created if needed; holds ``capture/``, ``renders/<map>_rot<deg>.{png,exr}`` and
        ``contact_sheet.png``.
    n_lights, resolution : int
        Size of the synthetic capture.
    maps : sequence of str
        Built-in light map names (:func:`ffls.lightmaps.lightmap.builtin_lightmap`).
    use_gpu : {'auto', True, False}
        'auto' uses the GPU engine where an OpenGL 4.3 context exists, else the CPU path.
    """
    from ffls.io.capture import load_capture, load_lights
    from ffls.io.images import write_exr, write_png
    from ffls.lightmaps.lightmap import builtin_lightmap
    from ffls.synth.scene import write_synthetic_capture
    from ffls.display.tonemap import tonemap, to_uint8

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    cap_dir = out / "capture"
    res = DemoResult(out_dir=out, capture_dir=cap_dir)

    t0 = time.perf_counter()
    write_synthetic_capture(cap_dir, n_lights=n_lights, resolution=resolution, seed=seed, progress=progress)
    res.seconds["synth"] = time.perf_counter() - t0

    capture = load_capture(cap_dir)
    lights = load_lights(cap_dir / "lights.json", capture)
    t0 = time.perf_counter()
    render, res.backend, release = _relighter(capture, lights, use_gpu)
    renders = out / "renders"
    renders.mkdir(exist_ok=True)
    tiles = []
    try:
        for name in maps:
            lm = builtin_lightmap(name)
            row, exposure = [], None
            for deg in rotations:
                hdr = render(lm, deg)
                if exposure is None:
                    exposure = auto_exposure(hdr)
                stem = renders / f"{name}_rot{int(round(deg)):03d}"
                write_exr(stem.with_suffix(".exr"), hdr)
                ldr = to_uint8(tonemap(hdr, exposure=exposure, method="aces"))
                write_png(stem.with_suffix(".png"), ldr)
                res.images[(name, deg)] = stem.with_suffix(".png")
                res.exrs[(name, deg)] = stem.with_suffix(".exr")
                row.append(ldr)
            tiles.append(row)
    finally:
        release()
    res.seconds["relight"] = time.perf_counter() - t0
    res.contact_sheet = contact_sheet(tiles, list(maps), [f"rotate {d:g} deg" for d in rotations],
                                      out / "contact_sheet.png")
    return res
