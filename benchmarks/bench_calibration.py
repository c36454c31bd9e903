"""Cost of the served intervals' calibration per estimator step: one ``resolve`` (score the
kept forecasts, decay, adaptive level, quantiles) and one ``halfwidth`` (the served
forecast's interval), all days pooled against per day class (docs/forecasts.md
"Intervals by day class"); and, given a model file and its telemetry, the served
forecast's run alone against the run and the weather-perturbed second run of the
intervals' std (docs/forecasts.md "Intervals that know the weather's error").

    python benchmarks/bench_calibration.py [--zones 6] [--steps 4000]
                                           [--model MODEL --telemetry CSV [--rows A:B]
                                            [--runner A:B]]

Synthetic scores (standard normal errors, model std 0.3 K) on a 15-min grid from
2015-01-01; the calendar is a Monday-to-Friday one in America/Chicago. The served forecast
is timed at the state after replaying telemetry rows A:B (default 5000:6500), 20 times.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import platform
import time
from pathlib import Path

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


def served(model: Path, telemetry: Path, rows: slice, reps: int = 20) -> tuple[float, float]:
    """Median seconds of a served forecast's run, and of the run plus the intervals' std
    with the weather's spread, at the state after replaying ``rows`` of ``telemetry``."""
    from zonecast.estimator.artifact import load_model_file
    from zonecast.estimator.streaming import OnlineEstimator, model_rows, telemetry_frame

    bundle = load_model_file(model)
    frame = telemetry_frame(telemetry, bundle)
    r = model_rows(bundle, frame[frame.notna().any(axis=1)].iloc[rows])
    est = OnlineEstimator(bundle)
    for k in range(len(r.times)):
        est.advance(r.times[k], r.u[k], r.v[k], r.y[k], r.reheat[k])
    if est.time is None:
        raise SystemExit("no telemetry row with data in --rows")
    ins, f = est.forecast_inputs(), est.dayahead_gains()
    control = est.reheat_control

    def run():
        return est._run_forecast(ins, f, control=control)

    def both():
        return est._served_std(ins, f, control, run())

    out = []
    for fn in (run, both):
        ts = []
        for _ in range(reps):
            t0 = time.perf_counter()
            fn()
            ts.append(time.perf_counter() - t0)
        out.append(float(np.median(ts)))
    return out[0], out[1]


def runner_steps(model: Path, telemetry: Path, rows: slice, cache: bool) -> tuple[float, int]:
    """Mean seconds of a runner's step (``advance`` and the served ``forecast``) over
    ``rows``, the served forecast at a step with a calibration forecast taken from it
    (``cache``, the estimator's behaviour) or computed afresh; and the steps with one."""
    from zonecast.estimator.artifact import load_model_file
    from zonecast.estimator.streaming import OnlineEstimator, model_rows, telemetry_frame

    bundle = load_model_file(model)
    frame = telemetry_frame(telemetry, bundle)
    r = model_rows(bundle, frame[frame.notna().any(axis=1)].iloc[rows])
    est = OnlineEstimator(bundle)
    due = 0
    t0 = time.perf_counter()
    for k in range(len(r.times)):
        est.advance(r.times[k], r.u[k], r.v[k], r.y[k], r.reheat[k])
        if est._due is not None and est._due[0][0] == est.time:
            due += 1
            if not cache:
                est._due = None
        if est.started:
            est.forecast()
    return (time.perf_counter() - t0) / len(r.times), due


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--zones", type=int, default=6)
    ap.add_argument("--steps", type=int, default=4000)
    ap.add_argument("--model", type=Path)
    ap.add_argument("--telemetry", type=Path)
    ap.add_argument("--rows", default="5000:6500")
    ap.add_argument("--runner", metavar="A:B",
                    help="also time a runner's steps over telemetry rows A:B (advance and the "
                         "served forecast each step), the served forecast at a due step afresh "
                         "against taken from the calibration forecast")
    args = ap.parse_args()
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores; {args.zones} zones, "
          f"{args.steps} steps")
    print("| calibration | resolve per step [µs] | halfwidth [µs] |")
    print("|---|---|---|")
    for split in (False, True):
        r, h = measure(split, args.zones, args.steps)
        print(f"| {'per day class' if split else 'all days pooled'} | {r * 1e6:.0f} | "
              f"{h * 1e6:.0f} |", flush=True)
    if args.model is not None and args.telemetry is not None:
        a, b = (int(x) for x in args.rows.split(":"))
        run, both = served(args.model, args.telemetry, slice(a, b))
        print(f"\nserved forecast ({args.model}, rows {args.rows}): run {run * 1e3:.1f} ms; "
              f"run and the weather-perturbed run {both * 1e3:.1f} ms")
        if args.runner:
            a, b = (int(x) for x in args.runner.split(":"))
            print("\n| runner step (advance and served forecast) | ms per step | steps with a "
                  "calibration forecast |\n|---|---|---|")
            for cache in (False, True):
                sec, due = runner_steps(args.model, args.telemetry, slice(a, b), cache)
                print(f"| {'served forecast reuses the calibration forecast' if cache else 'served forecast afresh'} "
                      f"| {sec * 1e3:.1f} | {due} |", flush=True)


if __name__ == "__main__":
    main()
