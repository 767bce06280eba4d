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

DEFAULT_MAPS = ("courtyard", "studio", "sunrise", "night", "sky", "paper")
DEFAULT_ROTATIONS = (0.0, 90.0, 180.0, 270.0)
#: What a demo folder holds; a folder holding anything else is not replaced.
DEMO_ENTRIES = ("capture", "renders", "contact_sheet.png")


@dataclass
class DemoResult:
    """Where the demo wrote its files, and how it rendered them."""

    out_dir: Path
    capture_dir: Path
    images: dict = field(default_factory=dict)  # (map name, rotation) -> PNG path
    exrs: dict = field(default_factory=dict)  # (map name, rotation) -> EXR path
    contact_sheet: Path | None = None
    backend: str = "cpu"  # 'gpu: <renderer>' or 'cpu'
    note: str | None = None  # why use_gpu='auto' fell back to the CPU (for the caller to report)
    seconds: dict = field(default_factory=dict)

    def moved(self, src: Path, dst: Path) -> "DemoResult":
        """The same result with every path under ``src`` (the staging folder) under ``dst``."""
        def move(p):
            return None if p is None else dst / Path(p).relative_to(src)

        return DemoResult(out_dir=dst, capture_dir=move(self.capture_dir),
                          images={k: move(v) for k, v in self.images.items()},
                          exrs={k: move(v) for k, v in self.exrs.items()}, contact_sheet=move(self.contact_sheet),
                          backend=self.backend, note=self.note, seconds=dict(self.seconds))


def _relighter(capture, lights, use_gpu):
    """The relighter for the demo: the GPU engine where it can run, else the CPU one.

    Returns
    -------
    relighter : ffls.gpu.engine.Engine or ffls.relight.cpu.CpuRelighter
    backend : str
        ``'gpu: <renderer>'`` or ``'cpu'``.
    release : callable
        Releases the relighter (and the context it made).
    note : str or None
        Why the GPU was not used, where ``use_gpu='auto'`` fell back to the CPU.
    """
    note = None
    if use_gpu in ("auto", True):
        try:
            from ffls.errors import GLUnavailable
            from ffls.gpu.context import create_headless_context
            from ffls.gpu.engine import Engine

            ctx = create_headless_context()
        except (GLUnavailable, ImportError) as e:
            if use_gpu is True:
                raise
            note = f"no GPU path ({e}); using the CPU relighter"
        else:
            engine = Engine.from_capture(ctx, capture, lights)

            def release():
                engine.release()
                ctx.release()

            return engine, f"gpu: {ctx.info['GL_RENDERER']}", release, None

    from ffls.relight.cpu import CpuRelighter

    cpu = CpuRelighter.from_capture(capture, lights, precision="f32")
    return cpu, "cpu", cpu.release, note


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
        Holds ``capture/``, ``renders/<map>_rot<deg>.{png,exr}`` and ``contact_sheet.png``. It is
        written as a whole in a staging folder and swapped in only when complete
        (:func:`ffls.errors.atomic_folder`): an interrupted demo leaves the old output or nothing.
        A folder holding anything else is refused (:class:`ffls.errors.InputError`).
    n_lights, resolution : int
        Size of the synthetic capture.
    maps : sequence of str
        Built-in light map names (:func:`ffls.lightmaps.lightmap.builtin_lightmap`).
    use_gpu : {'auto', True, False}
        'auto' uses the GPU engine where an OpenGL 4.3 context exists, else the CPU path.
    """
    from ffls.errors import InputError, atomic_folder

    out = Path(out_dir)
    if out.is_dir():
        other = sorted(p.name for p in out.iterdir() if p.name not in DEMO_ENTRIES)
        if other:
            raise InputError(f"holds other files than a demo's ({other[0]!r}, ...); refusing to replace it", out)
    with atomic_folder(out) as stage:
        res = _run_demo_into(Path(stage), n_lights, resolution, maps, rotations, use_gpu, seed, progress)
    return res.moved(Path(stage), out)


def _run_demo_into(out: Path, n_lights, resolution, maps, rotations, use_gpu, seed, progress) -> DemoResult:
    """:func:`run_demo`'s work, every file written under ``out`` (the staging folder)."""
    from ffls.io.capture import load_capture, load_lights
    from ffls.io.images import write_exr, write_png
    from ffls.lightmaps.lightmap import builtin_lightmap
    from ffls.synth.scene import write_synthetic_capture
    from ffls.conventions import rotation_z
    from ffls.display.tonemap import auto_exposure, tonemap, to_uint8

    cap_dir = out / "capture"
    res = DemoResult(out_dir=out, capture_dir=cap_dir)

    t0 = time.perf_counter()
    write_synthetic_capture(cap_dir, n_lights=n_lights, resolution=resolution, seed=seed, progress=progress)
    res.seconds["synth"] = time.perf_counter() - t0

    capture = load_capture(cap_dir)
    lights = load_lights(cap_dir / "lights.json", capture)
    t0 = time.perf_counter()
    relighter, res.backend, release, res.note = _relighter(capture, lights, use_gpu)
    renders = out / "renders"
    renders.mkdir(exist_ok=True)
    tiles = []
    try:
        for name in maps:
            lm = builtin_lightmap(name)
            row, exposure = [], None
            for deg in rotations:
                relighter.set_lightmap(lm)
                relighter.set_rotation(rotation_z(deg))
                relighter.render()
                hdr = relighter.read_hdr()
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
