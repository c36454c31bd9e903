"""Blind benchmark of `zonecast diagnose` (issue 6): virtual-building data with one effect the
model lacks, and clean controls.

The reference model is identified on a control campaign (reheat off, infiltration off: the two
effects the paper's model has no term for). Each scenario switches one effect on in the
virtual building (different effects, zones, magnitudes and seeds); the diagnosis runs on the
scenario's data with the control's model and must rank the true effect first. Controls
(other seeds, no effect added) must give no confident attribution.

The diagnosis of control_s0 (the identification campaign, the reference period) is the
reference of every other diagnosis (`zonecast diagnose --reference`): its confident effects —
the model's own structural gap to the virtual building — are added to the base model and its
internal-gains profile is kept; `--absolute` runs every scenario without it.

    python benchmarks/bench_diagnose.py [--out DIR] [--only NAME ...] [--absolute]

Prints one line per scenario, the confusion table, and writes DIR/bench_diagnose.json.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

# no discharge-air sensors: reheat must stay an effect the model cannot see (with them it is a
# measured input, docs/model.md)
NO_DAT = ["--disable", "discharge_sensors"]
CLEAN = ["--disable", "reheat", "--disable", "infiltration", *NO_DAT]
# name, seed, testbed switches on top of the control's, true effect (None: control)
SCENARIOS = [
    ("control_s1", 1, [], None),
    ("control_s2", 2, [], None),
    ("control_s3", 3, [], None),
    ("reheat_s0", 0, ["reheat"], "reheat"),
    ("reheat_s1", 1, ["reheat"], "reheat"),
    ("reheat_s2", 2, ["reheat"], "reheat"),
    ("infiltration_x1_s0", 0, ["--set", "infiltration=1"], "infiltration"),
    ("infiltration_x3_s1", 1, ["--set", "infiltration=3"], "infiltration"),
    ("infiltration_x2_s2", 2, ["--set", "infiltration=2"], "infiltration"),
    ("bias_W_+0.5_s0", 0, ["--set", "bias.W=0.5"], "sensor_bias"),
    ("bias_NE_-0.6_s1", 1, ["--set", "bias.NE=-0.6"], "sensor_bias"),
    ("bias_S_+0.4_s2", 2, ["--set", "bias.S=0.4"], "sensor_bias"),
    ("shgc_0.7_s0", 0, ["--set", "shgc=0.7"], "window_solar"),
    ("shgc_0.15_s1", 1, ["--set", "shgc=0.15"], "window_solar"),
    ("supply_offset_+1.0_s1", 1, ["--set", "supply_offset=1.0"], "supply_offset"),
    ("supply_offset_-1.5_s2", 2, ["--set", "supply_offset=-1.5"], "supply_offset"),
    ("gains_C_x1.5_s0", 0, ["--set", "gains.C=1.5"], "occupancy_gains"),
    ("gains_E_x0.5_s3", 3, ["--set", "gains.E=0.5"], "occupancy_gains"),
    # added after the method was frozen (2026-11-23) and run once: new seeds, zones, sizes
    ("reheat_s3", 3, ["reheat"], "reheat"),
    ("infiltration_x1.5_s3", 3, ["--set", "infiltration=1.5"], "infiltration"),
    ("bias_C_-0.4_s3", 3, ["--set", "bias.C=-0.4"], "sensor_bias"),
    ("bias_E_+0.3_s1", 1, ["--set", "bias.E=0.3"], "sensor_bias"),
    ("shgc_0.55_s2", 2, ["--set", "shgc=0.55"], "window_solar"),
    ("supply_offset_+0.6_s0", 0, ["--set", "supply_offset=0.6"], "supply_offset"),
    ("gains_NW_x1.3_s1", 1, ["--set", "gains.NW=1.3"], "occupancy_gains"),
    ("control_s4", 4, [], None),
    # thermal mass (testbed switch added after the method was frozen; run once)
    ("mass_S_x3_s1", 1, ["--set", "mass.S=3"], "thermal_mass"),
    ("mass_E_x4_s2", 2, ["--set", "mass.E=4"], "thermal_mass"),
    # air exchanged with neighbouring zones (switch added after the freeze; run once)
    ("mixing_S_0.1_s1", 1, ["--set", "mixing.S=0.1"], "interzone_air"),
    ("mixing_NE_0.05_s3", 3, ["--set", "mixing.NE=0.05"], "interzone_air"),
]


def campaign(zc: str, out: Path, seed: int, switches: list[str]) -> float:
    flags = CLEAN
    if switches and switches[0] == "reheat":  # reheat on: keep only "--disable infiltration"
        flags, switches = ["--disable", "infiltration", *NO_DAT], switches[1:]
    t = time.perf_counter()
    subprocess.run([zc, "testbed", "campaign", "--out", str(out), "--seed", str(seed),
                    *flags, *switches], check=True, capture_output=True)
    return time.perf_counter() - t


def _one(zc: str, root: Path, item, absolute: bool) -> dict:
    """Campaign (if missing) and diagnosis of one scenario; prints its line."""
    from zonecast.jobs.diagnosis import run

    name, seed, switches, truth = item
    ref = root / "control_s0"
    d = root / name
    t_camp = 0.0
    if not (d / "telemetry.csv").exists():
        t_camp = campaign(zc, d, seed, switches)
    t = time.perf_counter()
    # the reference period: control_s0, the campaign the model was identified on; its
    # diagnosis (absolute) is the reference of every other one
    use_ref = None if (absolute or name == "control_s0") else ref / "diagnosis" / "diagnosis.json"
    res = run(ref / "model.json", d, d / ("diagnosis" if use_ref is None else "diagnosis_ref"),
              reference=use_ref, site_path=d / "site.yaml")
    t_diag = time.perf_counter() - t
    top = res.ranked[0]
    conf = [c for c in res.ranked if c.confident]
    row = {"scenario": name, "seed": seed, "truth": truth, "top": top.effect,
           "top_zones": top.zones, "top_variant": top.variant, "top_confident": top.confident,
           "top_tied_with": top.tied_with,
           "top_score": top.score, "top_confidence": top.confidence,
           "confident_effects": [c.effect for c in conf],
           "truth_rank": next((i + 1 for i, c in enumerate(res.ranked)
                               if c.effect == truth), None),
           "heldout_before": top.heldout_rms_before["mean"],
           "heldout_after": top.heldout_rms_after["mean"],
           "campaign_s": t_camp, "diagnose_s": t_diag}
    if truth:
        tc = next(c for c in res.ranked if c.effect == truth)
        row.update(truth_zones=tc.zones, truth_score=tc.score,
                   truth_heldout_before=tc.heldout_rms_before["mean"],
                   truth_heldout_after=tc.heldout_rms_after["mean"])
    ok = (top.effect == truth) if truth else not conf
    print(f"{name:22s} truth={truth or '-':14s} top={top.effect:15s} {top.zones} "
          f"score={top.score:.3f} conf={top.confidence:.3f} "
          f"confident={[c.effect for c in conf]} heldout {top.heldout_rms_before['mean']:.3f}"
          f"->{top.heldout_rms_after['mean']:.3f} diag {t_diag:.0f}s {'OK' if ok else 'MISS'}",
          flush=True)
    return row


def _markdown(rows: list[dict], hits: int, n_scen: int, clean: int, n_ctrl: int,
              absolute: bool = False) -> str:
    """The scenario table and the confusion table as Markdown (docs/diagnosis.md)."""
    L = [("| scenario | true effect | top-ranked (zones) | score | tied with | confident "
          "effects | rank of the true effect | held-out RMS, true effect added [K] | pass |"),
         "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        truth = r["truth"]
        ok = (r["top"] == truth) if truth else not r["confident_effects"]
        if r["scenario"] == "control_s0" and not absolute:
            ok_s = "reference"
        else:
            ok_s = "yes" if ok else "no"
        zones = ", ".join(r["top_zones"]) if len(r["top_zones"]) < 6 else "all"
        held = (f"{r['truth_heldout_before']:.3f} → {r['truth_heldout_after']:.3f}"
                if truth else "–")
        L.append(f"| {r['scenario']} | {truth or 'control'} | {r['top']} ({zones}) | "
                 f"{r['top_score']:.3f} | {', '.join(r.get('top_tied_with', [])) or '–'} | "
                 f"{', '.join(r['confident_effects']) or 'none'} | {r['truth_rank'] or '–'} | "
                 f"{held} | {ok_s} |")
    scen = [r for r in rows if r["truth"]]
    effects = sorted({r["truth"] for r in scen})
    tops = sorted({r["top"] for r in scen})
    L += ["", (f"True effect ranked first: **{hits} of {n_scen}**; controls without a "
               f"confident attribution: **{clean} of {n_ctrl}**."), "",
          "| true \\ top | " + " | ".join(tops) + " |", "|---" * (len(tops) + 1) + "|"]
    for e in effects:
        L.append(f"| {e} | " + " | ".join(str(sum(r["top"] == t for r in scen
                                                   if r["truth"] == e)) for t in tops) + " |")
    return "\n".join(L) + "\n"


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", type=Path, default=Path("bench-diagnose"))
    ap.add_argument("--only", nargs="*")
    ap.add_argument("--jobs", type=int, default=1,
                    help="diagnose this many scenarios at once (after the reference)")
    ap.add_argument("--absolute", action="store_true",
                    help="no reference: diagnose every scenario against the bare model (the "
                         "controls then measure the model's structural gap)")
    args = ap.parse_args()
    zc = str(Path(sys.executable).with_name("zonecast"))
    root = args.out
    ref = root / "control_s0"
    if not (ref / "model.json").exists():
        print("control campaign (seed 0) and its identification ...", flush=True)
        campaign(zc, ref, 0, [])
        subprocess.run([zc, "identify", "--site", str(ref / "site.yaml"), "--data", str(ref),
                        "--out", str(ref / "model.json")], check=True, capture_output=True)
    todo = [t for t in [("control_s0", 0, [], None)] + SCENARIOS
            if not args.only or t[0] in args.only]
    # the reference diagnosis first: every other one reads it
    first = [t for t in todo if t[0] == "control_s0"]
    rest = [t for t in todo if t[0] != "control_s0"]
    if not args.absolute and rest and not (ref / "diagnosis" / "diagnosis.json").is_file():
        first = first or [("control_s0", 0, [], None)]
    rows = [_one(zc, root, t, args.absolute) for t in first]
    if args.jobs > 1:
        from concurrent.futures import ProcessPoolExecutor
        with ProcessPoolExecutor(args.jobs) as pool:
            rows += list(pool.map(_one, [zc] * len(rest), [root] * len(rest), rest,
                                  [args.absolute] * len(rest)))
    else:
        rows += [_one(zc, root, t, args.absolute) for t in rest]
    rows = [r for r in rows if not args.only or r["scenario"] in args.only]
    scen = [r for r in rows if r["truth"]]
    # control_s0 is the reference period itself (unless --absolute): not a blind control
    ctrl = [r for r in rows if not r["truth"] and (args.absolute or r["scenario"] != "control_s0")]
    hits = sum(r["top"] == r["truth"] for r in scen)
    clean = sum(not r["confident_effects"] for r in ctrl)
    print(f"\ntrue effect ranked first: {hits}/{len(scen)}; controls without a confident "
          f"attribution: {clean}/{len(ctrl)}")
    effects = sorted({r["truth"] for r in scen})
    tops = sorted({r["top"] for r in scen})
    print("confusion (rows: true effect, columns: top-ranked):")
    print(" " * 14 + " ".join(f"{t[:12]:>12s}" for t in tops))
    for e in effects:
        print(f"{e:14s}" + " ".join(f"{sum(r['top'] == t for r in scen if r['truth'] == e):12d}"
                                    for t in tops))
    (root / "bench_diagnose.md").write_text(_markdown(rows, hits, len(scen), clean, len(ctrl),
                                                          args.absolute))
    (root / "bench_diagnose.json").write_text(json.dumps(
        {"rows": rows, "hits": hits, "n_scenarios": len(scen), "clean_controls": clean,
         "n_controls": len(ctrl)}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
