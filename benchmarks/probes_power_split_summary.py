"""What rules for the least-power weight would have chosen, from ``probes_power_split.py``'s results.

    python benchmarks/probes_power_split_summary.py [RESULT.json ...]

Without arguments: every ``benchmarks/results/probes_power_split*.json``. Per rule, over all rows of all
files: the misses of 7% (relit synth capture), the worst and median relit error, and the rows worse than the
paired rule's (the default) by more than 0.1 point. The rules, each from the stored per-weight numbers:
``paired_se`` (the default: the cross-validation's own choice, stored), ``cv_min`` (lowest held-out total),
``paired_2se`` (the largest weight whose paired excess is within two standard errors), ``discrepancy`` (the
largest weight whose sum of squares over all pixels exceeds the lowest by at most one standard deviation of a
chi-square of that many terms, ``sqrt(2 N) s^2``, ``s^2`` the lowest sum over ``N``), each fixed weight, and
``oracle`` (the best weight per row: what a perfect choice among these weights would give). Then the split of
the default's error: the median share of its relit error that remains with the map's error in orders 0-2
alone. Reads only.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def choices(row) -> dict:
    """Index of the weight each rule takes on one row."""
    w = [x["weight"] for x in row["weights"]]
    S = np.asarray(row["fold_errors"], dtype=np.float64)  # the CV's weights: the first len(S) of w
    total = S.sum(axis=1)
    best = int(np.argmin(total))
    D = S - S[best]
    se = np.sqrt(S.shape[1]) * np.std(D, axis=1, ddof=1)
    rss = np.array([x["rss"] for x in row["weights"]])
    s2 = rss.min() / row["pixels"]
    out = {"paired_se": w.index(row["cv_weight"]), "cv_min": best,
           "paired_2se": int(np.flatnonzero(D.sum(axis=1) <= 2 * se)[-1]),
           "discrepancy": int(np.flatnonzero(rss - rss.min() <= np.sqrt(2 * row["pixels"]) * s2)[-1]),
           "oracle": int(np.argmin([x["relit"] for x in row["weights"]]))}
    out.update({f"fixed {x:g}": j for j, x in enumerate(w)})
    return out


def main(argv=None):
    files = list(argv if argv is not None else sys.argv[1:]) or sorted(
        (ROOT / "benchmarks/results").glob("probes_power_split*.json"))
    rows = [(Path(f).name, r) for f in files for r in json.loads(Path(f).read_text())["rows"]]
    err = {}
    for _, r in rows:
        for rule, j in choices(r).items():
            err.setdefault(rule, []).append(100 * r["weights"][j]["relit"])
    ref = np.asarray(err["paired_se"])
    print(f"{len(rows)} rows from {len(files)} files; relit synth capture %")
    for rule, e in err.items():
        e = np.asarray(e)
        print(f"  {rule:12s} misses of 7%: {int(np.sum(e > 7)):2d}  worst {e.max():5.1f}  median {np.median(e):4.1f}  "
              f"worse than paired_se by > 0.1: {int(np.sum(e > ref + 0.1)):2d}")
    print("misses of the default (paired_se):")
    for (f, r), e in zip(rows, ref):
        if e > 7:
            j = choices(r)["paired_se"]
            x = r["weights"][j]
            print(f"  {f} {r['map']} orientation {r['orientation']}: weight {r['cv_weight']:g} relit {e:.1f}%, "
                  f"orders 0-2 alone {100 * x['relit_orders_0_2']:.1f}%, above 2 alone "
                  f"{100 * x['relit_orders_above_2']:.1f}%; relit per weight "
                  + " / ".join(f"{100 * y['relit']:.1f}" for y in r["weights"])
                  + "; re-render per weight " + " / ".join(f"{y['rerender']:.5f}" for y in r["weights"]))
    share = [r["weights"][choices(r)["paired_se"]]["relit_orders_0_2"] / max(r["weights"][choices(r)["paired_se"]]
             ["relit"], 1e-12) for _, r in rows]
    print(f"orders 0-2 alone over the default's relit error: median {np.median(share):.2f}")


if __name__ == "__main__":
    main()
