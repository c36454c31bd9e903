"""Benchmark of the parameter identification (issue 4, paper section 4-A).

In one run, on the virtual building's campaign:
1. `identify` with the defaults of `zonecast identify` (3 starts, the default window-solar
   placement),
   repeated ``--repeat`` times: wall time, evaluations, training/validation RMS, spread of the
   starts' costs;
2. the reference side by side: the same identification of the paper's model (window solar on
   the room air), same data, same starts.

Usage: python benchmarks/bench_identify.py [--campaign DIR] [--repeat N] [--starts N]
(DIR is reused if it holds a campaign, else the campaign is run into it first.)
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices: threads only contend

import argparse
import platform
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
from zonecast.estimator.pipeline import Pipeline
from zonecast.estimator.rc.network import ModelOptions


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--campaign", type=Path)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--starts", type=int, default=3)
    args = ap.parse_args()
    camp = args.campaign or Path(tempfile.mkdtemp(prefix="zonecast-bench-")) / "campaign"
    if not (camp / "telemetry.csv").is_file():
        from zonecast.testbed.run import run_campaign
        print(f"running the campaign into {camp} ...", flush=True)
        run_campaign(camp, seed=0)
    pipe = Pipeline.from_site(camp / "site.yaml")
    tel = pipe.telemetry(camp / "telemetry.csv")
    pipe.building()  # read once, shared by both option sets
    print(f"python {platform.python_version()}, numpy {np.__version__}, {os.cpu_count()} cores, "
          f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS')}")
    default = ModelOptions()
    for label, options, repeat in (
            (f"default (window solar: {default.window_solar}, floor share {default.floor_share})",
             default, args.repeat),
            ("reference: paper (window solar on air)", ModelOptions(window_solar="air"), 1)):
        variant = pipe.with_options(options)
        data = variant.data(tel)
        times = []
        for _ in range(repeat):
            t = time.perf_counter()
            res = variant.identify(data, n_starts=args.starts)
            times.append(time.perf_counter() - t)
        costs = [s["cost"] for s in res.starts]
        print(f"{label}: {args.starts} starts, median {statistics.median(times):.1f} s "
              f"(runs {', '.join(f'{x:.1f}' for x in times)}), {res.n_evaluations} evaluations; "
              f"training RMS {res.train_rms['mean']:.3f}, validation "
              f"{res.validation_rms['mean']:.3f} degC; start costs "
              f"{', '.join(f'{c:.1f}' for c in costs)}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
