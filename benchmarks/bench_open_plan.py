"""Air boundaries as one solar enclosure, on open-plan copies of family members (issue 13).

EnergyPlus makes rooms joined by air boundaries (``Construction:AirBoundary``) one solar and
radiant enclosure; the model does the same since 2026-12-04 (``--solar-enclosure
air_boundaries``, docs/model.md "Air boundaries"). No family member has air boundaries, so this
benchmark makes open-plan copies of some: every wall between a south room (``S_*``) and a core
room (``C_*``) becomes an air boundary (simple mixing 0.5 ach), each VAV box's minimum flow is
made constant (``zonecast testbed foreign`` schedules it itself) and the member's own schedule
file is referenced by its path. The copy goes through ``zonecast testbed foreign`` (every room
its own model zone, the member's climate) and ``zonecast reproduce --no-sensitivity
--no-service`` twice, ``--solar-enclosure room`` and ``air_boundaries``; it prints training /
validation / fixed 24 h / day-ahead RMS of both.

    python benchmarks/bench_open_plan.py --family runs/family-m --out runs/open-plan \\
        --members office6 f0-01-chicago f0-07-sanfrancisco f0-09-tampa f0-10-golden

Needs EnergyPlus (the testbed extra); about 2 min per member on 2 cores.
"""

from __future__ import annotations

import argparse
import json
import platform
import shutil
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from zonecast.estimator.idf import idf_objects

#: the construction given to the walls made air boundaries
OPEN = "open_plan_air_boundary"
VARIANTS = ("room", "air_boundaries")


def open_plan_copy(member: Path, out: Path, groups: tuple[str, str] = ("S", "C")) -> int:
    """Write ``out/openplan.idf``: the member's input with the walls between rooms of the two
    ``groups`` (room-name prefixes) as air boundaries; return how many walls changed."""
    out.mkdir(parents=True, exist_ok=True)
    shutil.copy(member / "schedules.csv", out / "member_schedules.csv")
    objs = idf_objects((member / "building.idf").read_text())
    zone_of = {o[1]: o[4] for o in objs
               if o[0].lower() == "buildingsurface:detailed" and len(o) > 4}
    text, changed = [], 0
    for o in objs:
        cls = o[0].lower()
        if cls == "buildingsurface:detailed" and len(o) > 7 and o[6].lower() == "surface":
            rooms = {o[4].split("_")[0], zone_of.get(o[7], "").split("_")[0]}
            if rooms == set(groups):
                o = [*o[:3], OPEN, *o[4:]]
                changed += 1
        elif cls == "airterminal:singleduct:vav:reheat":
            o = [*o, *[""] * max(0, 10 - len(o))]
            o = [*o[:6], "Constant", "0.3", o[8], "", *o[10:]]
        elif cls == "schedule:file" and o[3] == "schedules.csv":
            o = [*o[:3], str((out / "member_schedules.csv").resolve()), *o[4:]]
        text.append(o[0] + ",\n    " + ",\n    ".join(o[1:]) + ";\n")
    text.append(f"Construction:AirBoundary,\n    {OPEN},\n    SimpleMixing,\n    0.5;\n")
    (out / "openplan.idf").write_text("\n".join(text))
    return changed


def _zonecast(*args: str) -> str:
    exe = Path(sys.executable).with_name("zonecast")
    res = subprocess.run([str(exe), *args], capture_output=True, text=True, check=False)
    if res.returncode != 0:
        raise RuntimeError(f"zonecast {' '.join(args)} failed:\n{res.stdout}\n{res.stderr}")
    return res.stdout


def _scores(report: Path) -> dict:
    res = json.loads((report / "results.json").read_text())
    t2, t3 = res["table2"], res["table3"]
    return {"training": t2["training"]["mean"], "validation": t2["validation"]["mean"],
            "fixed": t3["fixed"]["mean"], "dayahead": t3["dayahead"]["mean"]}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--family", type=Path, required=True)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--members", nargs="+", required=True)
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    rows = {}
    for name in args.members:
        work = args.out / name
        n = open_plan_copy(args.family / name, work)
        print(f"{name}: {n} walls made air boundaries", flush=True)
        _zonecast("testbed", "foreign", "--idf", str(work / "openplan.idf"),
                  "--out", str(work / "campaign"))
        runs = [("reproduce", "--campaign", str(work / "campaign"), "--out",
                 str(work / f"report-{v}"), "--no-sensitivity", "--no-service",
                 "--solar-enclosure", v) for v in VARIANTS]
        with ThreadPoolExecutor(args.jobs) as pool:
            list(pool.map(lambda a: _zonecast(*a), runs))
        rows[name] = {"walls": n, **{v: _scores(work / f"report-{v}") for v in VARIANTS}}
        r = rows[name]
        print("  " + "  ".join(f"{v}: " + " / ".join(f"{r[v][k]:.3f}" for k in
                                                    ("training", "validation", "fixed",
                                                     "dayahead")) for v in VARIANTS),
              flush=True)
    print(f"\nmachine: {platform.machine()}; {time.perf_counter() - t0:.0f} s")
    print("| member | walls | room: training / validation / fixed 24 h / day-ahead | "
          "air_boundaries |")
    print("|---|---|---|---|")
    for name, r in rows.items():
        cells = [" / ".join(f"{r[v][k]:.3f}" for k in ("training", "validation", "fixed",
                                                       "dayahead")) for v in VARIANTS]
        print(f"| {name} | {r['walls']} | {cells[0]} | {cells[1]} |")
    (args.out / "open_plan.json").write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
