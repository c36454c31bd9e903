"""Family benchmark (issue 13): the paper's pipeline on every building of a family of virtual
floors and on third-party EnergyPlus buildings, training and held-out members reported apart.

For each campaign folder (``telemetry.csv``, ``site.yaml``, ``truth.csv`` when the building is
virtual) it runs ``zonecast reproduce`` (identification, internal gains, Table 3 forecasts, the
service's forecast, gains-vs-truth) and collects, per building: Table 2 (training, validation),
Table 3 (fixed, day-ahead, service), the median per-zone r of the estimated gains against the
truth, the 90 % coverage of the served intervals, the parameters at a bound, and the
identification seconds. Then the median and the worst building per role (``train`` members
choose defaults; ``heldout`` and ``third_party`` members only report).

    python benchmarks/bench_family.py --family DIR [--extra CAMPAIGN ...] [--out DIR]
                                      [--jobs 2] [--starts 1] [--only NAME ...]

``DIR/index.json`` is written by ``zonecast testbed family``: a list of members (or
``{"members": [...]}``) with ``name`` and ``role``; each member's campaign is ``DIR/<name>``.
``--extra`` adds campaign folders of buildings the testbed did not write (role
``third_party``). Writes ``OUT/bench_family.json`` and ``OUT/bench_family.md`` and prints the
table. Reports already in ``OUT/<name>/results.json`` are reused unless ``--rerun``.

Studies of structure and identification that need Tables 2 and 3 and the gains only can
pass ``--reproduce-args "--no-sensitivity --no-service"``: the service check (the served
forecast with the thermostat model, most of a member's time) is left out and the service
and coverage columns show "–" (office6: 69 s per member instead of several minutes).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

#: musts of issue 13 (held-out members and third-party buildings) and the paper's numbers
TARGETS = {"training": 0.25, "validation": 0.30, "fixed": 0.35}
PAPER = {"training": 0.333, "validation": 0.413, "fixed": 0.485}


def members(family: Path | None, extra: list[Path]) -> list[dict]:
    out = []
    if family is not None:
        doc = json.loads((family / "index.json").read_text())
        items = doc["members"] if isinstance(doc, dict) else doc
        for m in items:
            out.append({"name": m["name"], "role": m.get("role", "train"),
                        "campaign": family / m["name"]})
    for path in extra:
        out.append({"name": path.name, "role": "third_party", "campaign": path})
    for m in out:
        if not (m["campaign"] / "telemetry.csv").is_file():
            raise SystemExit(f"{m['campaign']}: no telemetry.csv (run the campaign first)")
    return out


def run_one(zc: str, m: dict, out: Path, starts: int, rerun: bool,
            extra_args: list[str]) -> dict:
    report = out / m["name"]
    res_file = report / "results.json"
    t = time.perf_counter()
    if rerun or not res_file.is_file():
        proc = subprocess.run([zc, "reproduce", "--out", str(report), "--campaign",
                               str(m["campaign"]), "--starts", str(starts), *extra_args],
                              capture_output=True, text=True, check=False)
        if proc.returncode != 0:
            return {**m, "error": proc.stderr.strip().splitlines()[-1:] or ["failed"],
                    "seconds": time.perf_counter() - t}
    res = json.loads(res_file.read_text())
    t2, t3 = res["table2"], res["table3"]
    gains = [v["total"]["r"] for v in (res.get("gains_truth") or {}).values()
             if v.get("total", {}).get("r") is not None]
    # the served forecast's intervals: calibrated ones where reproduce reports them
    covs = res.get("coverage_90") or {}
    cov = covs.get("service_calibrated", covs.get("service"))
    return {
        **m, "campaign": str(m["campaign"]),
        "training": t2["training"]["mean"],
        "validation": (t2.get("validation") or {}).get("mean"),
        "fixed": t3["fixed"]["mean"], "dayahead": t3.get("dayahead", {}).get("mean"),
        "service": t3.get("service", {}).get("mean"),
        "gains_r_median": statistics.median(gains) if gains else None,
        "gains_r_min": min(gains) if gains else None,
        "coverage_service": cov.get("all") if isinstance(cov, dict) else cov,
        "at_bounds": [n for n, p in res["parameters"].items() if p.get("at_bound")],
        "identification_s": res.get("timings_s", {}).get("identification"),
        "seconds": time.perf_counter() - t,
    }


def summary(rows: list[dict]) -> dict:
    out = {}
    for role in sorted({r["role"] for r in rows}):
        ok = [r for r in rows if r["role"] == role and "error" not in r]
        if not ok:
            continue
        s = {"n": len(ok)}
        for key in ("training", "validation", "fixed", "dayahead", "service",
                    "gains_r_median", "coverage_service", "identification_s"):
            vals = [r[key] for r in ok if r.get(key) is not None]
            if vals:
                worst = min(vals) if key.startswith("gains") else max(vals)
                s[key] = {"median": statistics.median(vals), "worst": worst}
        s["with_params_at_bounds"] = sum(1 for r in ok if r["at_bounds"])
        out[role] = s
    return out


def _f(x, nd=3) -> str:
    return "–" if x is None else f"{x:.{nd}f}"


def markdown(rows: list[dict], summ: dict) -> str:
    head = ("| building | role | training | validation | fixed 24 h | day-ahead | service | "
            "gains r (median) | coverage 90 % | at bounds | ident. s |")
    lines = [head, "|---" * 11 + "|"]
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['name']} | {r['role']} | error: {r['error']} |||||||||")
            continue
        lines.append(f"| {r['name']} | {r['role']} | {_f(r['training'])} | "
                     f"{_f(r['validation'])} | {_f(r['fixed'])} | {_f(r['dayahead'])} | "
                     f"{_f(r['service'])} | {_f(r['gains_r_median'], 2)} | "
                     f"{_f(r['coverage_service'], 2)} | {', '.join(r['at_bounds']) or '–'} | "
                     f"{_f(r['identification_s'], 1)} |")
    head = ("| role | n | training median / worst | validation | fixed 24 h | "
            "gains r median / worst | with params at bounds |")
    lines += ["", head, "|---" * 7 + "|"]

    def mw(s: dict, key: str, nd: int = 3) -> str:
        v = s.get(key)
        return "–" if v is None else f"{_f(v['median'], nd)} / {_f(v['worst'], nd)}"

    for role, s in summ.items():
        lines.append(f"| {role} | {s['n']} | {mw(s, 'training')} | {mw(s, 'validation')} | "
                     f"{mw(s, 'fixed')} | {mw(s, 'gains_r_median', 2)} | "
                     f"{s['with_params_at_bounds']} |")
    musts = (f"Musts on held-out and third-party buildings: median training <= "
             f"{TARGETS['training']}, validation <= {TARGETS['validation']}, fixed <= "
             f"{TARGETS['fixed']} degC; worst <= the paper ({PAPER['training']} / "
             f"{PAPER['validation']} / {PAPER['fixed']}).")
    lines += ["", musts]
    return "\n".join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--family", type=Path)
    ap.add_argument("--extra", type=Path, nargs="*", default=[])
    ap.add_argument("--out", type=Path, default=Path("runs/bench_family"))
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--starts", type=int, default=1)
    ap.add_argument("--only", nargs="*")
    ap.add_argument("--rerun", action="store_true")
    ap.add_argument("--reproduce-args", default="--no-sensitivity",
                    help="extra arguments of zonecast reproduce, e.g. '--priors --window "
                         "experiments' (a variant to compare; default skips the paper-placement "
                         "sensitivity)")
    args = ap.parse_args()
    if args.family is None and not args.extra:
        ap.error("give --family DIR and/or --extra CAMPAIGN ...")
    zc = str(Path(sys.executable).with_name("zonecast"))
    todo = members(args.family, args.extra)
    if args.only:
        todo = [m for m in todo if m["name"] in args.only]
    args.out.mkdir(parents=True, exist_ok=True)
    print(f"{len(todo)} buildings, {args.jobs} at once, {args.starts} starts, reproduce "
          f"{args.reproduce_args!r}; reports in {args.out}", flush=True)
    t0 = time.perf_counter()
    rows: list[dict] = []
    with ThreadPoolExecutor(max_workers=args.jobs) as pool:
        extra = args.reproduce_args.split()
        for r in pool.map(lambda m: run_one(zc, m, args.out, args.starts, args.rerun, extra),
                          todo):
            rows.append(r)
            if "error" in r:
                print(f"{r['name']:<24} {r['role']:<11} ERROR {r['error']}", flush=True)
            else:
                print(f"{r['name']:<24} {r['role']:<11} train {_f(r['training'])} val "
                      f"{_f(r['validation'])} fixed {_f(r['fixed'])} service {_f(r['service'])} "
                      f"gains r {_f(r['gains_r_median'], 2)} bounds {len(r['at_bounds'])} "
                      f"({r['seconds']:.0f} s)", flush=True)
    summ = summary(rows)
    (args.out / "bench_family.json").write_text(json.dumps(
        {"rows": rows, "summary": summ, "seconds": time.perf_counter() - t0,
         "reproduce_args": args.reproduce_args, "starts": args.starts}, indent=1,
        default=str))  # a failed member's record holds its report path
    md = markdown(rows, summ)
    (args.out / "bench_family.md").write_text(md + "\n")
    print(md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
