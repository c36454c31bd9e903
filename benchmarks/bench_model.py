"""Benchmark: build + discretise the 5ZoneAirCooled model and simulate 11 weeks at 15 min.

Usage: python benchmarks/bench_model.py [path/to/5ZoneAirCooled.idf]

Synthetic but realistic inputs (seeded): VAV 0.05-1 kg/s per box changing hourly, supply
13 C, outdoor 5-30 C daily sine, facade solar 0-800 W/m2. Prints timings and the error of
the paper's fixed-matrix form against the exact per-step discretisation. The lead adds the
EnergyPlus side-by-side later.
"""

from __future__ import annotations

import os

# small dense matrices: BLAS threading only adds contention
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import platform
import sys
import time
from pathlib import Path

import numpy as np
from zonecast.estimator.idf import read_building
from zonecast.estimator.model import build_model

SEED = 20150601
WEEKS = 11


def synthetic_inputs(n_steps: int, n_boxes: int, n_zones: int, seed: int = SEED):
    rng = np.random.default_rng(seed)
    day = np.arange(n_steps) * 900.0 / 86400.0
    u = rng.uniform(0.05, 1.0, (n_steps // 4 + 1, n_boxes)).repeat(4, axis=0)[:n_steps]
    ta = 17.5 + 12.5 * np.sin(2 * np.pi * (day - 0.375))
    sun = np.clip(800 * np.sin(2 * np.pi * (day - 0.25)), 0, None)
    v = np.column_stack([ta, np.full(n_steps, 13.0), 0.7 * sun * (day % 1 < 0.5), sun,
                         0.7 * sun * (day % 1 >= 0.5), 0.15 * sun])
    f = np.where((day % 1 > 0.33) & (day % 1 < 0.75), 15.0, 0.0)[:, None] * np.ones(n_zones)
    return u, v, f


def main(path: str) -> None:
    t0 = time.perf_counter()
    building = read_building(path)
    t1 = time.perf_counter()
    zones = {"Perimeter": ["SPACE1-1", "SPACE2-1", "SPACE3-1", "SPACE4-1"], "Core": ["SPACE5-1"]}
    boxes = {f"VAV-{i}": f"SPACE{i}-1" for i in range(1, 6)}
    model = build_model(building, zones, boxes)
    model.step_matrices(np.full(5, 0.3))
    model.discrete_bilinear()
    t2 = time.perf_counter()
    n_steps = WEEKS * 7 * 96
    u, v, f = synthetic_inputs(n_steps, model.n_boxes, model.n_zones)
    x0 = model.steady_state(u[0], v[0], f[0])
    t3 = time.perf_counter()
    exact = model.simulate(x0, u, v, f)
    t4 = time.perf_counter()
    fixed = model.simulate(x0, u, v, f, method="bilinear")
    t5 = time.perf_counter()
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
          f"Python {platform.python_version()}, numpy {np.__version__}, seed {SEED}")
    print(f"states: {model.n} {model.structure.state_counts()}")
    print(f"read IDF (EnergyPlus convert): {t1 - t0:.2f} s")
    print(f"build + discretise:            {t2 - t1:.3f} s")
    print(f"simulate {n_steps} steps exact:   {t4 - t3:.2f} s")
    print(f"simulate {n_steps} steps bilinear:{t5 - t4:.2f} s")
    err = np.abs(fixed.y - exact.y)
    print(f"fixed-matrix (paper form) vs exact, zone temps: max {err.max():.3f} C, "
          f"RMS {np.sqrt((err ** 2).mean()):.3f} C")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else str(Path(__file__).resolve().parents[1] / "configs" / "sites" / "nrel" / "5ZoneAirCooled.idf"))
