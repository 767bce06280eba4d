"""``ffls lights CAPTURE``: estimate each photograph's light direction from the spheres."""
from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np

NAME = "lights"
HELP = "estimate each photo's light direction from the white spheres"
DESCRIPTION = ("Fit every photo's spheres (Lambert + ambient + ground bounce), combine them into one "
               "distant or near light, reject inconsistent photos, and write lights.json.")


def add_arguments(p):
    p.add_argument("capture", help="capture folder (with capture.json)")
    p.add_argument("-o", "--output", default=None, help="lights.json to write (default: CAPTURE/lights.json)")
    p.add_argument("--model", choices=("auto", "distant", "near"), default="auto",
                   help="light model: chosen per photo (auto), distant or near (default auto)")
    p.add_argument("--bounce", choices=("calibrated", "free"), default="calibrated",
                   help="ground bounce: each sphere's ground ratio calibrated over the capture and imposed "
                        "(two passes), or free per photo (default calibrated)")
    p.add_argument("--workers", type=int, default=None, help="processes (default: every core)")
    p.add_argument("--plot", default=None, metavar="PLOT.png",
                   help="draw the accepted directions and their Voronoi cells on the hemisphere")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def summary(lights) -> str:
    """One-paragraph summary: accepted, rejected by reason, median uncertainty."""
    n = len(lights)
    ok = lights.ok_mask
    reasons = Counter(r for r, s in zip(lights.reasons, lights.status) if s == "rejected")
    unc = [e.get("uncertainty_deg") for e, s in zip(lights.extra, lights.status) if s == "ok"]
    unc = [u for u in unc if u is not None]
    models = Counter(e.get("model") for e, s in zip(lights.extra, lights.status) if s == "ok")
    lines = [f"{int(ok.sum())} of {n} lights accepted"
             + (f" ({', '.join(f'{v} {k}' for k, v in sorted(models.items()))})" if models else "")]
    if reasons:
        lines.append("rejected: " + ", ".join(f"{k} {v}" for k, v in reasons.most_common()))
    if unc:
        lines.append(f"median uncertainty {float(np.median(unc)):.2f} deg")
    return "\n".join(lines)


def plot_lights(lights, path, hemisphere: str = "upper", res: int = 256) -> Path:
    """PNG of the accepted directions with their angular Voronoi cells on the concentric map."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..errors import atomic_output
    from ..sphere_maps import get_map
    from ..voronoi import assign_cells, bake_cells

    idx, d = lights.accepted()
    smap = get_map("concentric")
    fig, ax = plt.subplots(figsize=(6, 6), dpi=100)
    if len(d):
        cells = bake_cells(d, hemisphere="upper", res=res)
        dirs = smap.directions(res)
        lab = assign_cells(dirs.reshape(-1, 3), d, cells).reshape(dirs.shape[:2]).astype(float)
        valid = smap.valid_mask(res)
        lab[~valid] = np.nan
        rng = np.random.default_rng(0)
        perm = rng.permutation(len(d))
        ax.imshow(np.where(np.isnan(lab), np.nan, perm[np.nan_to_num(lab).astype(int)]), cmap="tab20",
                  origin="upper", interpolation="nearest", alpha=0.6)
        up = d[d[:, 2] >= 0]
        px = smap.to_pixel(up, res)
        ax.plot(np.asarray(px)[:, 0] - 0.5, np.asarray(px)[:, 1] - 0.5, "k.", ms=3)
    ax.set_title(f"{len(d)} light directions (concentric map, +Z at centre)")
    ax.set_axis_off()
    with atomic_output(path) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    return Path(path)


def run(args) -> int:
    from ..capture import load_capture, save_lights
    from ..spheres.estimate import estimate_lights

    cap = load_capture(args.capture)
    lights = estimate_lights(cap, progress=not args.no_progress, workers=args.workers, model=args.model,
                             bounce=args.bounce)
    out = Path(args.output) if args.output else cap.folder / "lights.json"
    save_lights(lights, out)
    print(summary(lights))
    print(f"wrote {out}")
    if args.plot:
        plot_lights(lights, args.plot, hemisphere=cap.hemisphere)
        print(f"wrote {args.plot}")
    return 0
