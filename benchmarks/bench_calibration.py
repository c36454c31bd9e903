"""Cost of the served intervals' calibration per estimator step: one ``resolve`` (score the
kept forecasts, decay, adaptive level, quantiles) and one ``halfwidth`` (the served
forecast's interval), all days pooled against per day class (docs/forecasts.md
"Intervals by day class").

    python benchmarks/bench_calibration.py [--zones 6] [--steps 4000]

Synthetic scores (standard normal errors, model std 0.3 K) on a 15-min grid from
2015-01-01; the calendar is a Monday-to-Friday one in America/Chicago.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import platform
import time

import numpy as np
from zonecast.estimator.calibration import IntervalCalibrator
from zonecast.estimator.constants import HORIZON, STEP
from zonecast.estimator.inputs_forecast import DayCalendar


def measure(split: bool, zones: int, steps: int) -> tuple[float, float]:
    """Mean seconds of one resolve (with a calibration forecast kept when due) and of
    one halfwidth."""
    cal = DayCalendar("America/Chicago", STEP)
    kw = {"day_class": lambda t: cal.slots(t) // cal.per_day, "n_classes": 2} if split else {}
    c = IntervalCalibrator(zones, HORIZON, cal.per_day, step_ns=STEP.value, **kw)
    rng = np.random.default_rng(0)
    std = np.full((HORIZON, zones), 0.3)
    mean = np.zeros((HORIZON, zones))
    k0 = 1420070400 * 10**9 // STEP.value
    for k in range(k0, k0 + 2 * HORIZON):  # warm: histograms filled, forecasts pending
        c.resolve(k, rng.standard_normal(zones), std)
        if c.due(k):
            c.add_forecast(k, mean)
    ys = rng.standard_normal((steps, zones))
    t0 = time.perf_counter()
    for i in range(steps):
        k = k0 + 2 * HORIZON + i
        c.resolve(k, ys[i], std)
        if c.due(k):
            c.add_forecast(k, mean)
    t1 = time.perf_counter()
    for i in range(steps // 10):
        c.halfwidth(k0 + i, std)
    t2 = time.perf_counter()
    return (t1 - t0) / steps, (t2 - t1) / (steps // 10)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--zones", type=int, default=6)
    ap.add_argument("--steps", type=int, default=4000)
    args = ap.parse_args()
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores; {args.zones} zones, "
          f"{args.steps} steps")
    print("| calibration | resolve per step [µs] | halfwidth [µs] |")
    print("|---|---|---|")
    for split in (False, True):
        r, h = measure(split, args.zones, args.steps)
        print(f"| {'per day class' if split else 'all days pooled'} | {r * 1e6:.0f} | "
              f"{h * 1e6:.0f} |", flush=True)


if __name__ == "__main__":
    main()
