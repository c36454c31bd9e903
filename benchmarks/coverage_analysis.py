"""How sure is a member's measured coverage, and what scale of its intervals would have
covered 90 %? (issue 15; docs/forecasts.md "How precise a member's coverage is").

Reads the ``.npz`` files ``bench_reheat_control.py --dump DIR`` writes (every served
forecast of a run: mean, 90 % interval, measurement, target time, day class) and prints per
run:

- the coverage of the 90 % intervals (all zones; the lowest and highest zone);
- its standard error by a bootstrap over the forecasts (each is one day of 24 h, the
  zones of a day together; ``--boot`` resamples), and the 90 % range of the bootstrap;
- the coverage on working days and on other days;
- the coverage by the local weekday of the forecast's issue (Monday .. Sunday; the
  campaign's validation weeks have none on Monday, so that column is empty there, and
  Tuesday's is the first after the gap between weeks);
- ``c90``: the factor on every half-width (about the interval's centre) that would have
  given 0.90 over the run, i.e. how far off the calibration's width was;
- when the run issued at several local hours (``bench_reheat_control.py --issue-hours``), a
  second table: the coverage by the issue's local hour, over the whole day ahead and in
  its three 8-h thirds of lead.

    python benchmarks/coverage_analysis.py DIR [DIR ...] [--pattern GLOB] [--boot 2000]
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

import numpy as np


def load(path: Path) -> dict:
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def coverage_stats(run: dict, n_boot: int = 2000, seed: int = 0) -> dict:
    """Coverage, its bootstrap standard error over the forecasts, and c90 of one run."""
    meas, lo, hi = run["meas"], run["lower"], run["upper"]
    ok = np.isfinite(meas) & np.isfinite(lo) & np.isfinite(hi)
    inside = (meas >= lo) & (meas <= hi) & ok
    n_in = inside.sum(axis=(1, 2)).astype(float)   # per forecast
    n_ok = ok.sum(axis=(1, 2)).astype(float)
    cov = n_in.sum() / n_ok.sum()
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, len(n_ok), size=(n_boot, len(n_ok)))
    boot = n_in[idx].sum(axis=1) / n_ok[idx].sum(axis=1)
    per_zone = inside.sum(axis=(0, 1)) / np.maximum(ok.sum(axis=(0, 1)), 1)
    other = run["other_days"][:, :, None] & ok
    work = ~run["other_days"][:, :, None] & ok
    mid, hw = (hi + lo) / 2, (hi - lo) / 2
    ratio = np.abs(meas - mid)[ok] / np.maximum(hw[ok], 1e-12)
    # by the forecast's day in its week of data (6 issues a week: Tuesday .. Sunday), to see
    # whether the calibration carried over a gap between weeks is what falls short
    pos = (run["issue_weekday"] if "issue_weekday" in run  # 0 Monday .. 6 Sunday
           else np.arange(len(n_ok)) % 6 + 1)
    by_day = [n_in[pos == d].sum() / n_ok[pos == d].sum() if n_ok[pos == d].sum() else np.nan
              for d in range(7)]
    # by the local hour (runs with several issue hours), whole day and 8-h thirds
    hours = run["issue_hour"] if "issue_hour" in run else np.zeros(len(n_ok), int)
    third = np.arange(meas.shape[1]) * 3 // meas.shape[1]
    by_hour = {}
    for hr in np.unique(hours):
        f = hours == hr
        cells = [(inside[f][:, third == t].sum(), ok[f][:, third == t].sum()) for t in range(3)]
        by_hour[int(hr)] = (n_in[f].sum() / max(n_ok[f].sum(), 1),
                            *(a / max(b, 1) for a, b in cells))
    return {"coverage": cov, "se": boot.std(ddof=1), "by_day": by_day, "by_hour": by_hour,
            "range90": tuple(np.quantile(boot, [0.05, 0.95])),
            "zones": (per_zone.min(), per_zone.max()),
            "working": (inside & work).sum() / max(work.sum(), 1),
            "other": (inside & other).sum() / max(other.sum(), 1),
            "c90": float(np.quantile(ratio, 0.90)), "n_forecasts": len(n_ok)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dirs", type=Path, nargs="+")
    ap.add_argument("--pattern", default="*.npz")
    ap.add_argument("--boot", type=int, default=2000)
    args = ap.parse_args()
    files = sorted(f for d in args.dirs for f in d.glob(args.pattern))
    if not files:
        raise SystemExit(f"no {args.pattern} in {[str(d) for d in args.dirs]}")
    print("| run | forecasts | coverage | SE (bootstrap) | 90 % range | zones | "
          "working / other days | c90 | by issue weekday (Mon .. Sun) |")
    print("|---|---|---|---|---|---|---|---|---|")
    rows = []
    for f in files:
        s = coverage_stats(load(f), args.boot)
        rows.append(s)
        print(f"| {f.stem} | {s['n_forecasts']} | {s['coverage']:.3f} | {s['se']:.3f} | "
              f"{s['range90'][0]:.3f}–{s['range90'][1]:.3f} | "
              f"{s['zones'][0]:.3f}–{s['zones'][1]:.3f} | "
              f"{s['working']:.3f} / {s['other']:.3f} | {s['c90']:.3f} | "
              f"{' '.join(f'{v:.2f}' if np.isfinite(v) else '–' for v in s['by_day'])} |")
    if any(len(r["by_hour"]) > 1 for r in rows):
        hrs = sorted({h for r in rows for h in r["by_hour"]})
        print("\n| run | " + " | ".join(f"issued {h:02d} h: day (0–8 / 8–16 / 16–24 h)"
                                       for h in hrs) + " |")
        print("|---|" + "---|" * len(hrs))
        for f, r in zip(files, rows):
            cells = [r["by_hour"].get(h) for h in hrs]
            print(f"| {f.stem} | " + " | ".join(
                "–" if c is None else f"{c[0]:.3f} ({c[1]:.2f} / {c[2]:.2f} / {c[3]:.2f})"
                for c in cells) + " |")
        med = [np.median([r["by_hour"][h][0] for r in rows if h in r["by_hour"]]) for h in hrs]
        print("median by issue hour: " + ", ".join(f"{h:02d} h {m:.3f}" for h, m in zip(hrs, med)))
    cov = np.array([r["coverage"] for r in rows])
    se = np.array([r["se"] for r in rows])
    c90 = np.array([r["c90"] for r in rows])
    with warnings.catch_warnings():  # a weekday without forecasts in every run: nan
        warnings.simplefilter("ignore", RuntimeWarning)
        by_day = np.nanmedian([r["by_day"] for r in rows], axis=0)
    print(f"\n{len(rows)} runs: median coverage {np.median(cov):.4f}, median |coverage − 0.90| "
          f"{np.median(np.abs(cov - 0.9)):.4f}, median SE {np.median(se):.4f}, "
          f"spread of coverage (SD over runs) {cov.std(ddof=1) if len(cov) > 1 else 0:.4f}, "
          f"median c90 {np.median(c90):.3f}; median by issue weekday (Mon .. Sun) "
          f"{' '.join(f'{v:.3f}' for v in by_day)}")


if __name__ == "__main__":
    main()
