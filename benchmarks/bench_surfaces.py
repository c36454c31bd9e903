"""How EnergyPlus's envelope faces exchange heat, against the paper's films (issue 13, item 5).

The paper's hull model gives each opaque face one inside film to the room air (gamma_IW,
gamma_floor, gamma_ceil: the handbook's combined convection + radiation values 8.3 / 6.1 /
9.3 W/m2K) and one outside film to the outdoor air (gamma_EW, 25 W/m2K), and each window one
air-to-air conductance U_win. EnergyPlus, which plays the building, balances every face
separately: convection with the air, long-wave with the room's other faces, and outside
convection plus long-wave with the air, the ground and the sky. This benchmark re-runs a
virtual building's EnergyPlus input (as the testbed wrote it, with its schedules and
weather) with the faces' outputs added, and prints, per envelope face of the chosen rooms
and per month, over the nights (21-06 h local, no sun):

* the face's heat loss [W/m2] and the effective air-to-air U [W/(m2 K)] it implies
  (loss over room air minus outdoor air) against the rated U of its layers with the
  handbook films (windows: EnergyPlus's U-factor);
* the share of that loss that reaches the inside face by convection from the room air
  (the rest arrives as long-wave from the room's other faces);
* the inside convection coefficient and the total outside coefficient (convection +
  long-wave to air, ground and sky) EnergyPlus used, over the dry rows (while it rains
  EnergyPlus wets the face and sets its convection to 1000 W/(m2 K));

per exterior face over all the run's dry rows, the outside convection and long-wave
coefficients and the share of wet rows;

and, for every face of the rooms (interior walls, floors, ceilings, windows and furniture
too), the inside convection coefficient over all the run's rows (mean, 10th and 90th
percentiles) and its mean by class of face.

    python benchmarks/bench_surfaces.py --campaign runs/family-m/f0-04-chicago --rooms N_1
        [--out runs/surfaces-f0-04.json] [--keep DIR]

Needs EnergyPlus (the testbed extra). One EnergyPlus run of the building's 11 weeks
(about 40 s on 2 cores).
"""

from __future__ import annotations

import argparse
import json
import platform
import shutil
import sqlite3
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
import yaml
from zonecast.testbed.run import energyplus_dir, run_energyplus

#: face outputs added to the building's input (EnergyPlus 25.2 names)
FACE_VARIABLES = (
    "Surface Inside Face Conduction Heat Transfer Rate",
    "Surface Inside Face Convection Heat Gain Rate",
    "Surface Inside Face Net Surface Thermal Radiation Heat Gain Rate",
    "Surface Inside Face Convection Heat Transfer Coefficient",
    "Surface Inside Face Temperature",
    "Surface Outside Face Temperature",
    "Surface Outside Face Convection Heat Transfer Coefficient",
    "Surface Outside Face Thermal Radiation to Air Heat Transfer Coefficient",
    "Surface Outside Face Thermal Radiation to Ground Heat Transfer Coefficient",
    "Surface Outside Face Thermal Radiation to Sky Heat Transfer Coefficient",
)
SITE_VARIABLES = ("Site Outdoor Air Drybulb Temperature", "Site Sky Temperature",
                  "Site Wind Speed")
NIGHT = (21, 6)  # local hours [21, 24) and [0, 6)
#: the handbook's combined films [W/(m2 K)] (the priors' means of gamma_IW, gamma_ceil, gamma_EW)
HANDBOOK_INSIDE = {"Wall": 8.3, "Roof": 9.3}
HANDBOOK_OUTSIDE = 25.0
#: EnergyPlus sets a face's outside convection coefficient to 1000 W/(m2 K) while it rains
#: (the face is wet; Engineering Reference, "Exterior/External Conduction"): such rows are
#: left out of the outside films' means and counted apart, or a few rainy hours would
#: dominate them
WET_FACE = 999.0


def add_outputs(idf: str) -> str:
    lines = [f"Output:Variable,*,{v},Timestep;" for v in FACE_VARIABLES + SITE_VARIABLES]
    lines.append("Output:Variable,*,Zone Mean Air Temperature,Timestep;")
    return idf + "\n" + "\n".join(lines) + "\n"


def read_series(sql: Path, keys: list[str]) -> pd.DataFrame:
    """Wide table (month, day, hour, minute) x 'KEY|Variable' of the given keys."""
    con = sqlite3.connect(sql)
    marks = ",".join("?" * len(keys))
    q = ("select t.Month m, t.Day d, t.Hour h, t.Minute mi, rdd.KeyValue k, rdd.Name n, "
         "rd.Value v from ReportData rd join ReportDataDictionary rdd on "
         "rd.ReportDataDictionaryIndex = rdd.ReportDataDictionaryIndex join Time t on "
         f"rd.TimeIndex = t.TimeIndex where upper(rdd.KeyValue) in ({marks})")
    df = pd.read_sql(q, con, params=[k.upper() for k in keys])
    con.close()
    df["key"] = df.k.str.upper() + "|" + df.n
    return df.pivot_table(index=["m", "d", "h", "mi"], columns="key", values="v")


def summarise(wide: pd.DataFrame, faces: pd.DataFrame, rated: dict[str, float]) -> list[dict]:
    idx = wide.index.to_frame(index=False)
    night = ((idx.h > NIGHT[0]) | (idx.h <= NIGHT[1])).to_numpy()
    months = idx.m.to_numpy()
    out = []
    for face in faces.itertuples():
        name, zone, area = face.SurfaceName.upper(), face.ZoneName.upper(), face.Area
        get = lambda var, key=name: wide.get(f"{key}|{var}")
        conv = get("Surface Inside Face Convection Heat Gain Rate")
        rad = get("Surface Inside Face Net Surface Thermal Radiation Heat Gain Rate")
        if conv is None or rad is None:
            continue
        loss = (conv + rad).to_numpy() / area  # what the face passes outwards [W/m2]
        t_room = wide[f"{zone}|Zone Mean Air Temperature"].to_numpy()
        t_out = wide["ENVIRONMENT|Site Outdoor Air Drybulb Temperature"].to_numpy()
        h_out = sum(get(v).to_numpy() for v in FACE_VARIABLES[6:])
        dry = get(FACE_VARIABLES[6]).to_numpy() < WET_FACE
        h_in = get("Surface Inside Face Convection Heat Transfer Coefficient").to_numpy()
        for m in np.unique(months):
            sel = night & (months == m) & (t_room - t_out > 5.0)
            if sel.sum() < 8 or not (sel & dry).any():
                continue
            dt = float(np.mean(t_room[sel] - t_out[sel]))
            q = float(np.mean(loss[sel]))
            out.append({"face": face.SurfaceName, "class": face.ClassName, "zone": face.ZoneName,
                        "area_m2": float(area), "month": int(m), "night_rows": int(sel.sum()),
                        "room_minus_outdoor_K": dt, "loss_W_m2": q,
                        "U_effective": q / dt, "U_rated": rated.get(name),
                        "convective_share": float(np.mean(conv.to_numpy()[sel]) / area / q)
                        if q else float("nan"),
                        "h_inside_convection": float(np.mean(h_in[sel])),
                        "h_outside_total": float(np.mean(h_out[sel & dry])),
                        "wet_rows": int((sel & ~dry).sum())})
    return out


def outside_films(wide: pd.DataFrame, faces: pd.DataFrame) -> list[dict]:
    """Every exterior face's outside coefficients [W/(m2 K)] over all the run's dry rows:
    convection and long-wave (to the air, the ground and the sky), and the share of wet
    rows (rain, convection set to 1000) left out."""
    out = []
    for face in faces.itertuples():
        conv = wide.get(f"{face.SurfaceName.upper()}|{FACE_VARIABLES[6]}")
        if conv is None:
            continue
        c = conv.to_numpy(float)
        dry = c < WET_FACE
        rad = sum(wide[f"{face.SurfaceName.upper()}|{v}"].to_numpy(float)
                  for v in FACE_VARIABLES[7:])
        out.append({"face": face.SurfaceName, "class": face.ClassName,
                    "convection": float(np.mean(c[dry])), "long_wave": float(np.mean(rad[dry])),
                    "wet_share": float(1.0 - dry.mean())})
    return out


def inside_convection(wide: pd.DataFrame, faces: pd.DataFrame) -> list[dict]:
    """Every face's inside convection coefficient [W/(m2 K)] over all the run's rows (mean,
    10th and 90th percentiles): what the model's convective films stand for."""
    out = []
    for face in faces.itertuples():
        h = wide.get(f"{face.SurfaceName.upper()}|"
                     "Surface Inside Face Convection Heat Transfer Coefficient")
        if h is None:
            continue
        v = h.to_numpy(float)
        out.append({"face": face.SurfaceName, "class": face.ClassName, "zone": face.ZoneName,
                    "area_m2": float(face.Area), "h_mean": float(np.nanmean(v)),
                    "h_p10": float(np.nanpercentile(v, 10)),
                    "h_p90": float(np.nanpercentile(v, 90))})
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--campaign", type=Path, required=True,
                    help="a testbed building folder (building.idf, building.yaml, eplus/) or a "
                         "third-party one (zonecast testbed foreign: building.idf, run.json)")
    ap.add_argument("--rooms", nargs="+", required=True, help="EnergyPlus zones to report")
    ap.add_argument("--out", type=Path)
    ap.add_argument("--keep", type=Path, help="keep the EnergyPlus run in this folder")
    args = ap.parse_args(argv)
    camp = args.campaign
    if (camp / "building.yaml").is_file():  # a testbed member
        weather = yaml.safe_load((camp / "building.yaml").read_text())["weather"]
    else:  # a third-party building (zonecast testbed foreign)
        weather = json.loads((camp / "run.json").read_text())["weather"]
    epdir = energyplus_dir()
    work = args.keep or Path(tempfile.mkdtemp(prefix="zonecast-surfaces-"))
    work.mkdir(parents=True, exist_ok=True)
    (work / "in.idf").write_text(add_outputs((camp / "building.idf").read_text()))
    shutil.copy(camp / "eplus" / "schedules.csv", work / "schedules.csv")
    t0 = time.perf_counter()
    t_ep = run_energyplus(work / "in.idf", epdir / "WeatherData" / weather, work)
    con = sqlite3.connect(work / "eplusout.sql")
    surf = pd.read_sql("select s.SurfaceName, s.ClassName, s.Area, s.ExtBoundCond, "
                       "z.ZoneName, s.ConstructionIndex from Surfaces s join Zones z on "
                       "s.ZoneIndex = z.ZoneIndex", con)
    cons = pd.read_sql("select ConstructionIndex, Name, Uvalue from Constructions", con)
    con.close()
    rooms = {r.upper() for r in args.rooms}
    faces = surf[surf.ZoneName.str.upper().isin(rooms) & (surf.ExtBoundCond == 0)
                 & surf.ClassName.isin(["Wall", "Roof", "Window"])]
    if faces.empty:
        raise SystemExit(f"no exterior faces in rooms {sorted(rooms)}")
    # rated U: windows EnergyPlus's U-factor (films included); opaque faces their layers'
    # conductance (EnergyPlus's nominal U, without films) with the handbook's films, as the
    # paper's model at its priors' means sees them
    rated = {}
    for f in faces.itertuples():
        row = cons[cons.ConstructionIndex == f.ConstructionIndex]
        if row.empty:
            continue
        u = float(row.Uvalue.iloc[0])
        if f.ClassName != "Window":
            inside = HANDBOOK_INSIDE.get(f.ClassName, HANDBOOK_INSIDE["Wall"])
            u = 1.0 / (1.0 / u + 1.0 / inside + 1.0 / HANDBOOK_OUTSIDE)
        rated[f.SurfaceName.upper()] = u
    inner = surf[surf.ZoneName.str.upper().isin(rooms)]  # every face, furniture included
    keys = ["ENVIRONMENT", *inner.SurfaceName.tolist(), *faces.ZoneName.unique().tolist()]
    wide = read_series(work / "eplusout.sql", keys)
    rows = summarise(wide, faces, rated)
    convection = inside_convection(wide, inner)
    films = outside_films(wide, faces)
    print(f"machine: {platform.machine()}; EnergyPlus {t_ep:.0f} s; {len(faces)} faces")
    print(f"{'face':30s} {'month':>5s} {'dT':>5s} {'loss':>6s} {'U_eff':>6s} {'U_rat':>6s} "
          f"{'conv':>5s} {'h_in':>5s} {'h_out':>6s}")
    for r in rows:
        u_r = r["U_rated"] if r["U_rated"] is not None else float("nan")
        print(f"{r['face']:30s} {r['month']:5d} {r['room_minus_outdoor_K']:5.1f} "
              f"{r['loss_W_m2']:6.1f} {r['U_effective']:6.2f} {u_r:6.2f} "
              f"{r['convective_share']:5.2f} {r['h_inside_convection']:5.2f} "
              f"{r['h_outside_total']:6.1f}")
    print(f"\noutside coefficients [W/(m2 K)] of the exterior faces, all dry rows\n"
          f"{'face':30s} {'class':8s} {'conv':>5s} {'lw':>5s} {'total':>6s} {'wet':>6s}")
    for r in films:
        print(f"{r['face']:30s} {r['class']:8s} {r['convection']:5.2f} {r['long_wave']:5.2f} "
              f"{r['convection'] + r['long_wave']:6.2f} {r['wet_share']:6.2%}")
    print(f"\ninside convection coefficient [W/(m2 K)] of every face, all rows\n"
          f"{'face':30s} {'class':14s} {'area':>7s} {'mean':>5s} {'p10':>5s} {'p90':>5s}")
    for r in convection:
        print(f"{r['face']:30s} {r['class']:14s} {r['area_m2']:7.1f} {r['h_mean']:5.2f} "
              f"{r['h_p10']:5.2f} {r['h_p90']:5.2f}")
    by_class: dict[str, list[float]] = {}
    for r in convection:
        by_class.setdefault(r["class"], []).append(r["h_mean"])
    print("by class (mean of the faces' means): " + ", ".join(
        f"{c} {np.mean(v):.2f}" for c, v in sorted(by_class.items())))
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps({"campaign": str(camp.name), "rooms": sorted(rooms),
                                        "machine": platform.machine(),
                                        "seconds": time.perf_counter() - t0, "rows": rows,
                                        "inside_convection": convection,
                                        "outside_films": films},
                                       indent=1))
    if args.keep is None:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
