"""Benchmark: wall time of the virtual building's 11-week campaign.

The reference measured in the same run is EnergyPlus's own simulation time; the rest is
zonecast's work (schedules, IDF, ExpandObjects, reading SQL, writing files).
Usage: python benchmarks/bench_testbed.py [--repeat N]
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time
from pathlib import Path

from zonecast.testbed.run import run_campaign


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    rows = []
    for i in range(args.repeat):
        with tempfile.TemporaryDirectory() as d:
            t0 = time.perf_counter()
            res = run_campaign(Path(d) / "c", seed=i)
            wall = time.perf_counter() - t0
            rows.append((wall, res.timings["energyplus_s"]))
            print(f"run {i}: campaign {wall:.1f} s, of which EnergyPlus {res.timings['energyplus_s']:.1f} s, "
                  f"{len(res.telemetry)} steps")
    walls = sorted(r[0] for r in rows)
    eps = sorted(r[1] for r in rows)
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}")
    print(f"11-week campaign: median {walls[len(walls) // 2]:.1f} s (min {walls[0]:.1f}, max {walls[-1]:.1f}); "
          f"EnergyPlus alone median {eps[len(eps) // 2]:.1f} s; target < 120 s")


if __name__ == "__main__":
    main()
