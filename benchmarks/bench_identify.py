"""Benchmark of the parameter identification (issues 4 and 13, paper section 4-A).

For each campaign: ``Pipeline.identify`` with the defaults of ``zonecast identify`` (MAP
with the IDF priors, the IDF's infiltration, at most 3 starts that stop once two agree),
repeated ``--repeat`` times (wall time, evaluations, starts run, Table 2 RMS), and the
reference side by side: the same fit with every start run (``agree_rtol=0``, the
identification before 2026-11-24's early stop).

Usage:
  python benchmarks/bench_identify.py [--campaign DIR] [--repeat N] [--starts N]
  python benchmarks/bench_identify.py --family runs/family [--extra runs/nrel5 ...]
(a single ``--campaign`` DIR is reused if it holds a campaign, else the campaign is run
into it first; ``--family`` takes every member of a ``zonecast testbed family`` folder.)
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices: threads only contend

import argparse
import json
import platform
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
from zonecast.estimator.pipeline import Pipeline


def _campaigns(args) -> list[tuple[str, str, Path]]:
    if args.family is None:
        camp = args.campaign or Path(tempfile.mkdtemp(prefix="zonecast-bench-")) / "campaign"
        if not (camp / "telemetry.csv").is_file():
            from zonecast.testbed.run import run_campaign
            print(f"running the campaign into {camp} ...", flush=True)
            run_campaign(camp, seed=0)
        return [(camp.name, "campaign", camp)]
    index = json.loads((args.family / "index.json").read_text())
    out = [(m["name"], m["role"], args.family / m["name"]) for m in index["members"]
           if m.get("status", "ok") == "ok"]
    out += [(p.name, "third_party", p) for p in args.extra]
    if args.only:
        out = [c for c in out if c[0] in args.only]
    return out


def _one(camp: Path, starts: int, repeat: int, agree: float):
    pipe = Pipeline.from_site(camp / "site.yaml")
    data = pipe.data(pipe.telemetry(camp / "telemetry.csv"))
    times, res = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        res = pipe.identify(data, n_starts=starts, agree_rtol=agree)
        times.append(time.perf_counter() - t)
    return times, res


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--campaign", type=Path)
    ap.add_argument("--family", type=Path, help="a `zonecast testbed family` folder")
    ap.add_argument("--extra", type=Path, nargs="*", default=[],
                    help="more campaign folders (e.g. NREL's files from `testbed foreign`)")
    ap.add_argument("--only", nargs="*", help="member names to run")
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--starts", type=int, default=1)
    ap.add_argument("--no-reference", action="store_true",
                    help="skip the reference fit with every start run")
    args = ap.parse_args()
    print(f"python {platform.python_version()}, numpy {np.__version__}, {os.cpu_count()} cores, "
          f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS')}, load "
          f"{os.getloadavg()[0]:.2f}", flush=True)
    print("| building | role | default: s (median) | evaluations | starts run | Table 2 "
          "training / validation | reference (all starts): s | evaluations | Table 2 |")
    print("|---|---|---|---|---|---|---|---|---|")
    worst = 0.0
    for name, role, camp in _campaigns(args):
        t_def, r_def = _one(camp, args.starts, args.repeat, 1e-3)
        t_ref, r_ref = (None, None) if args.no_reference else _one(camp, args.starts, 1, 0.0)
        med = statistics.median(t_def)
        worst = max(worst, med)
        print(f"| {name} | {role} | {med:.1f} | {r_def.n_evaluations} | {len(r_def.starts)} | "
              f"{r_def.train_rms['mean']:.3f} / {r_def.validation_rms['mean']:.3f} | "
              + ("– | – | – |" if r_ref is None else
                 f"{t_ref[0]:.1f} | {r_ref.n_evaluations} | {r_ref.train_rms['mean']:.3f} / "
                 f"{r_ref.validation_rms['mean']:.3f} |"), flush=True)
    print(f"slowest default identification: {worst:.1f} s (target <= 30 s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
