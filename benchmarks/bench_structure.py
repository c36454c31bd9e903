"""Model structures against EnergyPlus with known gains and no fitting (issue 13, item 5).

Identification bends parameters to absorb what a structure lacks, so a structure's
Table 2 after fitting says little about its physics. This benchmark takes the fit out:
for each virtual building of a family (its ``truth.csv`` holds the internal gains
EnergyPlus simulated) and each structure variant, the model gets the parameters the
building's description and the handbooks give (the priors' means:
:func:`~zonecast.estimator.priors.building_priors`, window U and SHGC from the IDF), no
background gain (c_IG = 0) and the true internal gains as f_IG (people + lights +
equipment heat of each zone [W] / its floor area); per whole week x(0) comes from the
Kalman filter over the first day (with those gains), then the model runs open loop for six
days with the recorded airflows, weather and discharge air. Per building: the RMS [K] of
the open-loop zone temperatures against the measured ones, per zone and mean, and the mean
error by period (working-day nights, the 8 h warm-up, afternoons, weekends, winter, summer)
of the perimeter zones and the others; per variant: the median and worst over the buildings.

Variants are ``structure:films[:gains]``: ``none`` or ``star``
(``ModelOptions.interior_radiation``) or ``envelope`` (``ModelOptions.envelope_radiation
= "room"``) and ``combined`` (the handbook's convection + radiation
films) or ``convective`` (:data:`~zonecast.estimator.priors.CONVECTIVE_FILMS`) or three
numbers ``iw/floor/ceil`` [W/(m2 K)], e.g. ``none:1.4/1.4/0.9``; then optionally ``air``
(the default) or ``idf`` (``ModelOptions.internal_gains``: the IDF's radiant split), and
optionally ``lumped`` (the default) or ``fine`` (``ModelOptions.layers``: constructions in
sections of at most an hour's diffusion time), e.g. ``star:convective:air:fine``.

    python benchmarks/bench_structure.py --family DIR [--only NAME ...] [--extra CAMPAIGN ...]
        [--variants none:combined none:convective star:convective] [--out FILE.json]

``--extra`` adds campaign folders of buildings the testbed did not generate (``zonecast
testbed foreign``, which also writes ``truth.csv``), role ``third_party``.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices: threads only contend

import argparse
import json
import platform
import statistics
import time
from pathlib import Path

import numpy as np
import pandas as pd
from zonecast.estimator.forecast import whole_weeks, zone_floor_area
from zonecast.estimator.identify import kalman_state
from zonecast.estimator.internal_gains import truth_column
from zonecast.estimator.pipeline import Pipeline
from zonecast.estimator.priors import building_priors
from zonecast.estimator.rc.network import LAYERS, ModelOptions
from zonecast.estimator.rc.parameters import ParameterSet

#: the truth's parts that the model's f_IG stands for
GAIN_PARTS = ("people", "lights", "equipment")
FILMS = ("gamma_IW", "gamma_floor", "gamma_ceil")


def parse_variant(text: str) -> tuple[str, dict[str, float] | str, str, str]:
    """``"none:combined"`` -> ("none", "combined", "air", "lumped");
    ``"star:1.4/1.4/0.9:idf:fine"`` -> ("star", {...}, "idf", "fine")."""
    parts = text.split(":")
    if len(parts) not in (2, 3, 4):
        raise SystemExit(f"variant {text!r}: write structure:films[:gains[:layers]], "
                         "e.g. none:combined")
    structure, films = parts[:2]
    gains = parts[2] if len(parts) >= 3 else "air"
    layers = parts[3] if len(parts) == 4 else "lumped"
    if layers not in LAYERS:
        raise SystemExit(f"variant {text!r}: layers must be one of {', '.join(LAYERS)}")
    if structure not in ("none", "star", "envelope"):
        raise SystemExit(f"variant {text!r}: structure must be 'none', 'star' or 'envelope'")
    if gains not in ("air", "idf"):
        raise SystemExit(f"variant {text!r}: gains must be 'air' or 'idf'")
    if films in ("combined", "convective"):
        return structure, films, gains, layers
    try:
        values = [float(v) for v in films.split("/")]
    except ValueError:
        values = []
    if len(values) != 3 or min(values) <= 0:
        raise SystemExit(f"variant {text!r}: films must be 'combined', 'convective' or three "
                         "positive numbers iw/floor/ceil")
    return structure, dict(zip(FILMS, values)), gains, layers


def true_gains(campaign: Path, data, model) -> np.ndarray:
    """f_IG [W/m2] per row and zone: the truth's people (sensible) + lights + equipment heat
    / floor."""
    truth = pd.read_csv(campaign / "truth.csv", index_col=0)
    truth.index = pd.to_datetime(truth.index, utc=True)
    truth = truth.reindex(data.times)
    area = zone_floor_area(model)
    out = np.zeros((len(data.times), len(data.zones)))
    for j, z in enumerate(data.zones):
        cols = [c for c in (truth_column(truth.columns, p, f"zone:{z}") for p in GAIN_PARTS)
                if c in truth]
        if not cols:
            raise SystemExit(f"{campaign}: truth.csv has no gains of zone {z!r}")
        out[:, j] = np.nan_to_num(truth[cols].to_numpy(float)).sum(axis=1) / area[j]
    return out


def open_loop(campaign: Path, structure: str, films, gains: str = "air",
              layers: str = "lumped") -> dict:
    """Open-loop RMS per zone and mean of one building with one variant."""
    envelope = structure == "envelope"
    pipe = Pipeline.from_site(campaign / "site.yaml",
                              options=ModelOptions(
                                  interior_radiation="none" if envelope else structure,
                                  envelope_radiation="room" if envelope else "none",
                                  internal_gains=gains, layers=layers))
    data = pipe.data(campaign / "telemetry.csv")
    start = ParameterSet(list(pipe.site.zones))
    priors = building_priors(start, pipe._building_or_none(),
                             convective=films == "convective")
    values = {name: p.mean for name, p in priors.items()}
    if isinstance(films, dict):
        values.update(films)
    values.update({f"c_IG[{z}]": 0.0 for z in pipe.site.zones})
    model = pipe.model(start.copy(values))
    f_ig = true_gains(campaign, data, model)
    day = 96
    errs, times = [], []
    for week in whole_weeks(data):
        a, b = week["rows"]
        x0 = kalman_state(model, data, a, a + day, f_ig=f_ig)
        s = slice(a + day, b)
        y = model.simulate(x0, data.u[s], data.v[s], f_ig[s], reheat=data.reheat[s]).y
        meas = data.y[a + day + 1:b]  # the week's own rows (row b may open the next segment)
        errs.append(y[1:1 + len(meas)] - meas)
        times.append(data.times[a + day + 1:b])
    err = np.concatenate(errs)
    ok = np.isfinite(err)
    rms = np.sqrt((np.where(ok, err, 0.0) ** 2).sum(axis=0) / np.maximum(ok.sum(axis=0), 1))
    building = pipe._building_or_none()
    windowed = set() if building is None else {w.zone for w in building.windows.values()}
    perimeter = [j for j, z in enumerate(data.zones)
                 if windowed & set(pipe.site.zones[z])]
    return {"zones": dict(zip(data.zones, rms.round(4).tolist())),
            "mean": float(rms.mean()), "films": {k: values[k] for k in FILMS},
            "bias": bias_by_period(err, pd.DatetimeIndex(np.concatenate(times)), data.timezone,
                                   data.zones, perimeter)}


#: periods of the bias breakdown: name -> (working days only, local hours [from, to), months)
PERIODS = {
    "night": (True, (0, 6), None),          # working-day nights, the building at rest
    "08h": (True, (8, 9), None),            # the morning warm-up
    "afternoon": (True, (12, 18), None),
    "weekend": (False, None, None),
    "winter": (None, None, (12, 1, 2)),
    "summer": (None, None, (5, 6, 7, 8, 9)),
}


def bias_by_period(err: np.ndarray, times: pd.DatetimeIndex, tz: str, zones: list[str],
                   perimeter: list[int]) -> dict:
    """Mean model - measured [K] per period (:data:`PERIODS`, local time, Monday-Friday as
    working days) of each zone, and of the perimeter zones (those with windows) and the
    others taken together: where in the day and the year a structure's error lies."""
    local = times.tz_convert(tz)
    working = np.asarray(local.day_of_week < 5)
    hour, month = np.asarray(local.hour), np.asarray(local.month)
    groups = {"perimeter": perimeter, "core": [j for j in range(len(zones)) if j not in perimeter]}
    out: dict = {}
    for name, (workday, hours, months) in PERIODS.items():
        sel = np.ones(len(times), bool)
        if workday is not None:
            sel &= working if workday else ~working
        if hours is not None:
            sel &= (hour >= hours[0]) & (hour < hours[1])
        if months is not None:
            sel &= np.isin(month, months)
        part = err[sel]
        per_zone = np.nanmean(part, axis=0) if len(part) else np.full(len(zones), np.nan)
        out[name] = {**{z: round(float(v), 3) for z, v in zip(zones, per_zone)},
                     **{g: (round(float(np.nanmean(part[:, js])), 3) if js and len(part)
                            else None) for g, js in groups.items()}}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--family", type=Path, default=None, help="folder with index.json")
    ap.add_argument("--extra", type=Path, nargs="*", default=[],
                    help="campaign folders of third-party buildings")
    ap.add_argument("--only", nargs="*", default=None, help="member names (default all)")
    ap.add_argument("--variants", nargs="+",
                    default=["none:combined", "none:convective", "star:convective"])
    ap.add_argument("--out", type=Path, default=None, help="JSON file of the results")
    args = ap.parse_args()
    variants = [(v, *parse_variant(v)) for v in args.variants]
    members = []
    if args.family is not None:
        doc = json.loads((args.family / "index.json").read_text())
        members = [{**m, "campaign": args.family / m["name"]}
                   for m in (doc["members"] if isinstance(doc, dict) else doc)]
        if args.only:
            unknown = sorted(set(args.only) - {m["name"] for m in members})
            if unknown:
                raise SystemExit(f"not in the family: {unknown}")
            members = [m for m in members if m["name"] in args.only]
    members += [{"name": p.name, "role": "third_party", "campaign": p} for p in args.extra]
    if not members:
        raise SystemExit("give --family or --extra")
    missing = [m["name"] for m in members if not (m["campaign"] / "truth.csv").is_file()]
    if missing:
        raise SystemExit(f"no truth.csv (the true gains) for {missing}")
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores; {len(members)} buildings, "
          f"variants {[v for v, *_ in variants]}", flush=True)
    rows = []
    for m in members:
        row = {"name": m["name"], "role": m.get("role", "train")}
        for label, structure, films, gains, layers in variants:
            t = time.perf_counter()
            res = open_loop(m["campaign"], structure, films, gains, layers)
            row[label] = res
            print(f"{m['name']:22s} {label:22s} open-loop RMS {res['mean']:.3f} K "
                  f"({time.perf_counter() - t:.1f} s)", flush=True)
        rows.append(row)
    print()
    print("| building | role | " + " | ".join(v for v, *_ in variants) + " |")
    print("|---|---|" + "---|" * len(variants))
    for r in rows:
        print(f"| {r['name']} | {r['role']} | "
              + " | ".join(f"{r[v]['mean']:.3f}" for v, *_ in variants) + " |")
    for role in sorted({r["role"] for r in rows}):
        sel = [r for r in rows if r["role"] == role]
        print(f"| **median {role}** ({len(sel)}) | | "
              + " | ".join(f"{statistics.median(r[v]['mean'] for r in sel):.3f} / worst "
                           f"{max(r[v]['mean'] for r in sel):.3f}" for v, *_ in variants) + " |")
    print("\nMean model - measured [K] by period (working-day nights 0-6 h, 8 h, afternoons "
          "12-18 h; weekends; Dec-Feb; May-Sep), perimeter zones (with windows) / the others:")
    print("| building | variant | " + " | ".join(PERIODS) + " |")
    print("|---|---|" + "---|" * len(PERIODS))
    for r in rows:
        for v, *_ in variants:
            b = r[v]["bias"]
            cells = [" / ".join("–" if b[p][g] is None else f"{b[p][g]:+.2f}"
                                for g in ("perimeter", "core")) for p in PERIODS]
            print(f"| {r['name']} | {v} | " + " | ".join(cells) + " |")
    if args.out:
        args.out.write_text(json.dumps({"variants": args.variants, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
