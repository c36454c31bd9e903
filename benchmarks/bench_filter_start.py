"""Benchmark: what the streaming estimator computes once per model before its first step.

For a model file (``zonecast identify`` / ``reproduce`` output), times the steady-state
filter's parts (``streaming._steady_parts``: the Riccati equation and the forecast output
variances) and the young filter's gains after a start (``streaming._young_parts``,
``kalman.young_filter``), each from an empty cache, ``--repeat`` times (median; the first,
cold run is printed too). docs/benchmarks.md "The young filter after a restart".

    python benchmarks/bench_filter_start.py MODEL.json [--repeat 3]
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time
from pathlib import Path

from zonecast.estimator import streaming
from zonecast.estimator.artifact import load_model_file
from zonecast.estimator.kalman import air_wall_covariance, default_measurement_noise


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("model", type=Path)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    bundle = load_model_file(args.model)
    m, ns = bundle.model, bundle.noise
    Q = air_wall_covariance(m.n, m.structure.air_states(measured_only=True), ns.sigma_air,
                            ns.sigma_wall)
    R = default_measurement_noise(m.n_zones, sigma=ns.sigma_meas)
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, load "
          f"{os.getloadavg()[0]:.1f}; {m.n} states, {m.n_zones} zones", flush=True)
    steady, young, steps = [], [], 0
    for _ in range(max(args.repeat, 1)):
        streaming._STEADY.clear()
        t = time.perf_counter()
        parts = streaming._steady_parts(bundle, Q, R)
        steady.append(time.perf_counter() - t)
        t = time.perf_counter()
        steps = streaming._young_parts(bundle, parts).steps
        young.append(time.perf_counter() - t)
    print(f"steady-state parts: median {statistics.median(steady):.2f} s (cold {steady[0]:.2f} s)")
    print(f"young filter ({steps} steps): median {statistics.median(young):.2f} s "
          f"(cold {young[0]:.2f} s)")


if __name__ == "__main__":
    main()
