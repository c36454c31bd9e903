"""A first site description drafted from a building's EnergyPlus input (``zonecast site
draft``; docs/data.md "Drafting a site description").

A new user has an EnergyPlus file of the building and a building management system's
point list. The site description (:class:`~zonecast.estimator.site.Site`) ties the two
together; most of it is already in the EnergyPlus file: which zones are conditioned and by
which air terminals (VAV boxes), which terminals have a reheat coil (their discharge-air
temperature is worth measuring), where the building stands, and the thermostats' set point
schedules. :func:`draft_site` reads those and returns a valid site description whose
telemetry point names follow one convention (``T_<zone>``, ``<box>_flow``, ``<box>_DAT``,
``AHU_SAT``, ``OAT``, ``GHI``, ``DNI``, ``DHI``, ``CLOUD``; the testbed's,
:func:`point_names`), which the user then renames to the BMS's columns, with notes on
everything that was guessed or left out.

How the file is traced (EnergyPlus Input Output Reference, "Zone Equipment"):
``ZoneHVAC:EquipmentConnections`` -> ``ZoneHVAC:EquipmentList`` ->
``ZoneHVAC:AirDistributionUnit`` -> its ``AirTerminal:*`` object; a zone is a model zone when
a ``ZoneControl:Thermostat`` controls it (directly or through a ``ZoneList``) and an air
terminal serves it. The thermostat: the zones' ``ThermostatSetpoint:DualSetpoint`` (else the
single heating / cooling set point objects) and their ``Schedule:Compact`` or
``Schedule:Constant`` schedules, evaluated with :class:`~zonecast.estimator.schedules.
CompactSchedule` on a January week (heating) and a July week (cooling) and read as the two
levels :class:`~zonecast.estimator.site.Thermostat` holds.
"""

from __future__ import annotations

import datetime as dt
import os
import re
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from zoneinfo import ZoneInfo

import yaml
from pydantic import ValidationError
from zonecast.estimator.idf import load_epjson
from zonecast.estimator.schedules import CompactSchedule, ScheduleError
from zonecast.estimator.site import Site, Thermostat

__all__ = ["DraftError", "SiteDraft", "TerminalLink", "draft_site", "draft_thermostat",
           "epjson_objects", "find_name", "local_timezone", "point_names", "safe_name",
           "zone_terminals"]

#: IANA zone of a US standard UTC offset [h], for files that observe daylight saving time
US_ZONES = {-5.0: "America/New_York", -6.0: "America/Chicago", -7.0: "America/Denver",
            -8.0: "America/Los_Angeles", -9.0: "America/Anchorage", -10.0: "Pacific/Honolulu"}
#: days of the weeks the thermostat schedules are read on (a Monday in January and in July;
#: the year only fixes the weekdays, EnergyPlus's compact schedules are by date and day type)
HEATING_WEEK = dt.date(2015, 1, 12)
COOLING_WEEK = dt.date(2015, 7, 13)
#: thermostat objects of a ZoneControl:Thermostat, in the order they are preferred
_SETPOINT_TYPES = ("ThermostatSetpoint:DualSetpoint", "ThermostatSetpoint:SingleHeating",
                   "ThermostatSetpoint:SingleCooling")


class DraftError(ValueError):
    """The EnergyPlus input lacks what a site description needs; the message says what."""


@dataclass(frozen=True)
class TerminalLink:
    """An air terminal serving a thermostat-controlled zone.

    Attributes
    ----------
    zone : the EnergyPlus zone it serves.
    kind : its object type as the schema spells it (e.g. ``AirTerminal:SingleDuct:VAV:Reheat``).
    name : its object name.
    reheat_coil : its reheat coil's name, if it has one.
    """
    zone: str
    kind: str
    name: str
    reheat_coil: str | None = None


@dataclass
class SiteDraft:
    """A drafted site description: ``site`` (validated), ``notes`` (what was guessed or left
    out, for the user) and ``document`` (the fields as written to YAML)."""
    site: Site
    document: dict
    notes: list[str]

    def to_yaml_text(self) -> str:
        """The YAML file: a header of what to check, then the fields."""
        head = ["# Site description drafted by `zonecast site draft` from the EnergyPlus input.",
                "# Before use: rename every `point` to your BMS's telemetry column and set its",
                "# `unit` (degC/degF/K, kg/s, m3/s, cfm, L/s, W/m2); delete the",
                "# `discharge_temperature` of boxes whose discharge air you do not measure;",
                "# check the timezone and the thermostat; a model zone may group several rooms.",
                "# Then: zonecast check --site THIS_FILE --data TELEMETRY"]
        head += [f"# note: {n}" for n in self.notes]
        body = yaml.safe_dump(self.document, sort_keys=False, allow_unicode=True)
        return "\n".join(head) + "\n" + body


def epjson_objects(data: Mapping, kind: str) -> dict[str, dict]:
    """The objects of type ``kind`` in epJSON ``data`` (name -> fields), {} if none."""
    return data.get(kind) or {}


def find_name(table: Mapping[str, Any], name: str) -> str | None:
    """The key of ``table`` equal to ``name`` ignoring case (EnergyPlus names are)."""
    up = str(name).upper()
    return next((k for k in table if k.upper() == up), None)


def _zone_list(data: Mapping, name: str) -> list[str]:
    """The zones a ``Zone`` or ``ZoneList`` name stands for (upper case)."""
    lists = epjson_objects(data, "ZoneList")
    key = find_name(lists, name)
    if key is None:
        return [str(name).upper()]
    return [str(z.get("zone_name", "")).upper() for z in lists[key].get("zones", [])]


def zone_terminals(data: Mapping) -> tuple[list[TerminalLink], list[str]]:
    """The air terminals of the thermostat-controlled zones of epJSON ``data``.

    Returns
    -------
    terminals : list of TerminalLink
        In the order of the equipment connections and lists.
    skipped : list of str
        Zones with a thermostat but no air terminal, and equipment that is not an air
        distribution unit (baseboards, fan coils ...), each with the reason.
    """
    adus = epjson_objects(data, "ZoneHVAC:AirDistributionUnit")
    lists = epjson_objects(data, "ZoneHVAC:EquipmentList")
    zones = epjson_objects(data, "Zone")
    controlled = {z for f in epjson_objects(data, "ZoneControl:Thermostat").values()
                  for z in _zone_list(data, f.get("zone_or_zonelist_name", ""))}
    out: list[TerminalLink] = []
    skipped: list[str] = []
    served = set()
    for conn in epjson_objects(data, "ZoneHVAC:EquipmentConnections").values():
        zone = find_name(zones, conn.get("zone_name", ""))
        lst = find_name(lists, conn.get("zone_conditioning_equipment_list_name", ""))
        if zone is None or lst is None or zone.upper() not in controlled:
            continue
        for eq in lists[lst].get("equipment", []):
            etype = str(eq.get("zone_equipment_object_type", ""))
            if etype.upper() != "ZONEHVAC:AIRDISTRIBUTIONUNIT":
                skipped.append(f"{zone}: {etype} {eq.get('zone_equipment_name', '')} is not an "
                               "air terminal (its heat is not a model input)")
                continue
            key = find_name(adus, eq.get("zone_equipment_name", ""))
            if key is None:
                skipped.append(f"{zone}: air distribution unit {eq.get('zone_equipment_name')} "
                               "is not defined")
                continue
            adu = adus[key]
            kind = str(adu.get("air_terminal_object_type", ""))
            kind = next((k for k in data if k.upper() == kind.upper()), kind)
            tkey = find_name(epjson_objects(data, kind), adu.get("air_terminal_name", ""))
            fields = epjson_objects(data, kind).get(tkey, {}) if tkey else {}
            name = tkey or str(adu.get("air_terminal_name", ""))
            out.append(TerminalLink(zone, kind, name, fields.get("reheat_coil_name")))
            served.add(zone.upper())
    for z in sorted(controlled):
        if z not in served and find_name(zones, z) is not None:
            skipped.append(f"{find_name(zones, z)}: thermostat but no air terminal (not a model "
                           "zone: the model's HVAC input is the boxes' airflow)")
    return out, skipped


def safe_name(name: str) -> str:
    """``name`` with characters other than letters, digits, ``_``, ``.`` and ``-`` as ``_``."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name)


def point_names(zones: list[str], boxes: list[str]) -> dict:
    """Telemetry column names of the convention: ``T_<zone>``, ``<box>_flow``,
    ``<box>_DAT``, ``AHU_SAT``, ``OAT``, ``GHI``, ``DNI``, ``DHI``, ``CLOUD`` (characters
    other than letters, digits, ``_``, ``.`` and ``-`` become ``_``)."""
    used: set[str] = {"AHU_SAT", "OAT", "GHI", "DNI", "DHI", "CLOUD"}

    def unique(name: str) -> str:  # "A 1" and "A_1" must not share a column
        out, i = name, 2
        while out.upper() in used:
            out, i = f"{name}_{i}", i + 1
        used.add(out.upper())
        return out

    return {"temp": {z: unique(f"T_{safe_name(z)}") for z in zones},
            "flow": {b: unique(f"{safe_name(b)}_flow") for b in boxes},
            "discharge": {b: unique(f"{safe_name(b)}_DAT") for b in boxes},
            "sat": "AHU_SAT", "oat": "OAT", "ghi": "GHI", "dni": "DNI", "dhi": "DHI",
            "cloud": "CLOUD"}


def local_timezone(data: Mapping, utc_offset: float, timezone: str | None = None) -> str:
    """IANA time zone of the building's schedules: ``timezone`` if given; with the file's
    ``RunPeriodControl:DaylightSavingTime``, the US zone of the standard offset; without it
    the fixed offset (``Etc/GMT+6`` for UTC-6: EnergyPlus then keeps standard time all year).

    Raises
    ------
    DraftError
        Daylight saving time at an offset without a US zone, or a fractional offset,
        without ``timezone``.
    """
    if timezone is not None:
        ZoneInfo(timezone)
        return timezone
    if epjson_objects(data, "RunPeriodControl:DaylightSavingTime"):
        if utc_offset not in US_ZONES:
            raise DraftError(f"daylight saving time at UTC{utc_offset:+g}: give the site's IANA "
                             "time zone (--timezone, e.g. Europe/Berlin)")
        return US_ZONES[utc_offset]
    if utc_offset != int(utc_offset):
        raise DraftError(f"UTC offset {utc_offset} h: give the site's IANA time zone (--timezone)")
    return f"Etc/GMT{-int(utc_offset):+d}" if utc_offset else "Etc/GMT"


def _schedule(data: Mapping, name: str) -> CompactSchedule | float | None:
    """A set point schedule: a constant, a parsed compact schedule, or None if its type is
    not read here."""
    key = find_name(epjson_objects(data, "Schedule:Constant"), name)
    if key is not None:
        return float(epjson_objects(data, "Schedule:Constant")[key].get("hourly_value", 0.0))
    key = find_name(epjson_objects(data, "Schedule:Compact"), name)
    if key is not None:
        return CompactSchedule.from_epjson(key, epjson_objects(data, "Schedule:Compact")[key])
    return None


def _week(sched: CompactSchedule | float, monday: dt.date) -> list[list[tuple[float, float, float]]]:
    """Per day of the week from ``monday``: [(start hour, end hour, value)]."""
    if isinstance(sched, float):
        return [[(0.0, 24.0, sched)] for _ in range(7)]
    days = []
    for i in range(7):
        start, spans = 0.0, []
        for until, value in sched.day_values(monday + dt.timedelta(days=i)):
            spans.append((start, until / 60.0, float(value)))
            start = until / 60.0
        days.append(spans)
    return days


def _two_levels(week: list[list[tuple[float, float, float]]], high: bool
                ) -> tuple[float, float, tuple[float, float], list[int], list[str]]:
    """Occupied / unoccupied levels, occupied hours and working days of a week of set
    points: unoccupied is the setback (the lowest heating, the highest cooling set point of
    the week), occupied the other level held longest (a warm-up boost or a ramp step is
    shorter); the occupied hours span that level's first start to its last end on the days
    it occurs."""
    notes: list[str] = []
    held: Counter = Counter()
    for day in week:
        for a, b, v in day:
            held[v] += b - a
    levels = sorted(held)
    unocc = levels[0] if high else levels[-1]
    others = [v for v in levels if v != unocc]
    occ = max(others, key=lambda v: (held[v], v if high else -v)) if others else unocc
    days = [i for i, day in enumerate(week) if any(v == occ for (_, _, v) in day)] \
        if others else []
    starts = [a for i in days for (a, _, v) in week[i] if v == occ]
    ends = [b for i in days for (_, b, v) in week[i] if v == occ]
    hours = (min(starts), max(ends)) if days else (0.0, 24.0)
    if len(levels) > 2:
        notes.append(f"{len(levels)} set point levels {levels} read as two ({occ} occupied, "
                     f"{unocc} unoccupied)")
    spans = {(round(a, 2), round(b, 2)) for i in days for (a, b, v) in week[i] if v == occ}
    if len(spans) > 1:
        notes.append(f"occupied hours differ between days; drafted as {hours[0]:g}-{hours[1]:g} h")
    return occ, unocc, hours, days, notes


def draft_thermostat(data: Mapping, zones: list[str]) -> tuple[dict | None, list[str]]:
    """The site's ``thermostat`` section from the set point schedules of ``zones``' thermostats
    (the set most zones use), or None with the reason in the notes."""
    controls = epjson_objects(data, "ZoneControl:Thermostat")
    upper = {z.upper() for z in zones}
    pairs: Counter = Counter()
    for f in controls.values():
        if not upper.intersection(_zone_list(data, f.get("zone_or_zonelist_name", ""))):
            continue
        objs = {}
        for i in range(1, 5):
            kind, name = f.get(f"control_{i}_object_type"), f.get(f"control_{i}_name")
            if kind and name:
                objs[str(kind).upper()] = name
        heat = cool = None
        dual_key = "THERMOSTATSETPOINT:DUALSETPOINT"
        if dual_key in objs:
            table = epjson_objects(data, "ThermostatSetpoint:DualSetpoint")
            d = table.get(find_name(table, objs[dual_key]) or "", {})
            heat = d.get("heating_setpoint_temperature_schedule_name")
            cool = d.get("cooling_setpoint_temperature_schedule_name")
        for kind, attr in (("ThermostatSetpoint:SingleHeating", "heat"),
                           ("ThermostatSetpoint:SingleCooling", "cool")):
            if kind.upper() in objs and (heat if attr == "heat" else cool) is None:
                table = epjson_objects(data, kind)
                d = table.get(find_name(table, objs[kind.upper()]) or "", {})
                name = d.get("setpoint_temperature_schedule_name")
                heat, cool = (name, cool) if attr == "heat" else (heat, name)
        pairs[(heat, cool)] += 1
    if not pairs:
        return None, ["thermostat not drafted: no ZoneControl:Thermostat of the model zones "
                      "names a set point object read here (" + ", ".join(_SETPOINT_TYPES) + ")"]
    (heat, cool), _ = pairs.most_common(1)[0]
    notes = []
    if len(pairs) > 1:
        notes.append(f"the zones' thermostats use {len(pairs)} different set point schedule "
                     f"pairs; drafted from the most common ({heat}, {cool})")
    if heat is None:
        return None, [*notes, "thermostat not drafted: no heating set point schedule"]
    try:
        hs = _schedule(data, heat)
        cs = _schedule(data, cool) if cool else None
    except ScheduleError as exc:
        return None, [*notes, f"thermostat not drafted: {exc}"]
    if hs is None:
        return None, [*notes, (f"thermostat not drafted: heating set point schedule {heat} "
                               "is not a Schedule:Compact or Schedule:Constant")]
    try:
        h_occ, h_unocc, hours, days, n1 = _two_levels(_week(hs, HEATING_WEEK), high=True)
        cool_levels = None if cs is None else _two_levels(_week(cs, COOLING_WEEK), high=False)
    except ScheduleError as exc:
        return None, [*notes, f"thermostat not drafted: {exc}"]
    notes += [f"heating: {n}" for n in n1]
    out: dict = {"heating_occupied": h_occ, "heating_unoccupied": h_unocc}
    if cool_levels is not None:
        c_occ, c_unocc, c_hours, c_days, n2 = cool_levels
        notes += [f"cooling: {n}" for n in n2]
        out.update(cooling_occupied=c_occ, cooling_unoccupied=c_unocc)
        if h_occ == h_unocc:          # no heating setback: the cooling schedule tells the hours
            hours, days = c_hours, c_days
    if h_occ == h_unocc and out.get("cooling_occupied") == out.get("cooling_unoccupied"):
        notes.append("the set points do not change over the week: occupied hours are the "
                     "default")
        return out, notes
    out.update(occupied_hours=[float(hours[0]), float(hours[1])], working_days=days)
    return _valid_thermostat(out, notes)


def _valid_thermostat(out: dict, notes: list[str]) -> tuple[dict | None, list[str]]:
    """``out`` if it is a valid thermostat section; else without its cooling set points
    (files often write 99 degC for "cooling off"), else None; with a note either way."""
    try:
        Thermostat.model_validate(out)
        return out, notes
    except ValidationError as exc:
        why = "; ".join(f"{'.'.join(map(str, e['loc']))}: {e['msg']}" for e in exc.errors())
    heating = {k: v for k, v in out.items() if not k.startswith("cooling")}
    if len(heating) < len(out):
        try:
            Thermostat.model_validate(heating)
            return heating, [*notes, (f"cooling set points left out ({why}; a sentinel such as "
                                     "99 degC reads as 'cooling off')")]
        except ValidationError:
            pass
    return None, [*notes, f"thermostat not drafted: the set points read are out of range ({why})"]


def draft_site(idf: str | os.PathLike, *, out: str | os.PathLike | None = None,
               timezone: str | None = None, energyplus_dir: str | os.PathLike | None = None,
               data: Mapping | None = None) -> SiteDraft:
    """Draft a site description from an EnergyPlus input.

    Parameters
    ----------
    idf : path
        The building's EnergyPlus input (IDF or epJSON; read with EnergyPlus's converter).
    out : path, optional
        Where the site file will be written; the ``idf`` field is relative to its folder.
    timezone : str, optional
        IANA time zone; default from ``Site:Location`` and the daylight saving rule.
    energyplus_dir : path, optional
        EnergyPlus installation used to read an IDF.
    data : mapping, optional
        The file's epJSON data if already read.

    Raises
    ------
    DraftError
        No thermostat-controlled zone with an air terminal, no ``Site:Location``, or a time
        zone that cannot be derived.
    """
    idf = Path(idf)
    if data is None:
        data, _ = load_epjson(idf, energyplus_dir)
    terminals, notes = zone_terminals(data)
    if not terminals:
        raise DraftError(f"{idf.name}: no thermostat-controlled zone is served by an air terminal "
                         "(ZoneHVAC:EquipmentConnections -> ZoneHVAC:EquipmentList -> "
                         "ZoneHVAC:AirDistributionUnit); the model's HVAC input is the boxes' "
                         "airflow. " + "; ".join(notes))
    sites = list(epjson_objects(data, "Site:Location").values())
    if not sites:
        raise DraftError(f"{idf.name} has no Site:Location: add one (latitude, longitude, "
                         "time zone, elevation) or write the site's location by hand")
    loc = sites[0]
    tz = local_timezone(data, float(loc.get("time_zone", 0.0)), timezone)
    if timezone is None:
        notes.append(f"timezone {tz} from Site:Location's UTC offset "
                     f"{float(loc.get('time_zone', 0.0)):+g} h"
                     + (" and the file's daylight saving rule" if tz in US_ZONES.values() else ""))
    zones = list(dict.fromkeys(t.zone for t in terminals))
    boxes = [t.name for t in terminals]
    names = point_names(zones, boxes)
    others = [t for t in terminals if not t.kind.upper().startswith("AIRTERMINAL:SINGLEDUCT:")]
    if others:
        notes.append("terminals other than single-duct ones (their airflow is the zone supply "
                     "as well, but check what your BMS measures): "
                     + ", ".join(f"{t.name} ({t.kind})" for t in others))
    target = Path(out) if out is not None else Path("site.yaml")
    try:
        rel = os.path.relpath(idf.resolve(), target.resolve().parent)
    except ValueError:  # another drive
        rel = str(idf.resolve())
    doc: dict[str, Any] = {
        "building": safe_name(idf.stem).replace(".", "-"),
        "idf": rel,
        "timezone": tz,
        "location": {"latitude": float(loc.get("latitude", 0.0)),
                     "longitude": float(loc.get("longitude", 0.0)),
                     "elevation": float(loc.get("elevation", 0.0))},
        "step": "15min",
        "zones": {z: [z] for z in zones},
        "boxes": {t.name: {"room": t.zone,
                           "airflow": {"point": names["flow"][t.name], "unit": "kg/s"},
                           **({"discharge_temperature": {"point": names["discharge"][t.name],
                                                         "unit": "degC"}}
                              if t.reheat_coil else {})}
                  for t in terminals},
        "points": {
            "zone_temperature": {z: [{"point": names["temp"][z], "unit": "degC", "room": z}]
                                 for z in zones},
            "supply_air_temperature": {"point": names["sat"], "unit": "degC"},
            "outdoor_air_temperature": {"point": names["oat"], "unit": "degC"},
            "solar": {"global_horizontal": {"point": names["ghi"], "unit": "W/m2"},
                      "direct_normal": {"point": names["dni"], "unit": "W/m2"},
                      "diffuse_horizontal": {"point": names["dhi"], "unit": "W/m2"}},
            "cloud_cover": {"point": names["cloud"], "unit": "%"}},
    }
    notes.append("cloud_cover: CLOUD is the sky's opaque cloud cover in % (a weather "
                 "service's, e.g. Open-Meteo's cloud_cover, or a station's in okta or "
                 "tenths); the model's sky uses it with --sky cloud; delete the line if the "
                 "site has no such reading")
    loops = epjson_objects(data, "AirLoopHVAC")
    if len(loops) > 1:
        notes.append(f"{len(loops)} air loops ({', '.join(loops)}): `supply_air_temperature` is "
                     "one point; map it to the loop serving most boxes or to the boxes' flow-"
                     "weighted mean supply temperature")
    thermostat, tnotes = draft_thermostat(data, zones)
    notes += tnotes
    if thermostat is not None:
        doc["thermostat"] = thermostat
    if float(loc.get("latitude", 0.0)) == 0.0:
        notes.append("check the location: Site:Location reads latitude 0")
    epws = sorted(idf.resolve().parent.glob("*.epw"))
    if len(epws) == 1:
        # EnergyPlus users keep the weather file beside the input: the F/C-factor faces'
        # ground temperatures come from it (docs/data.md, weather_file)
        try:
            doc["weather_file"] = os.path.relpath(epws[0], target.resolve().parent)
        except ValueError:  # another drive
            doc["weather_file"] = str(epws[0])
        notes.append(f"weather_file {epws[0].name}: the one EPW beside the input")
    elif len(epws) > 1:
        notes.append(f"{len(epws)} EPW files beside the input: set weather_file to the one the "
                     "building is simulated with (its ground temperatures)")
    site = Site.model_validate({**doc, "base_dir": target.resolve().parent})
    return SiteDraft(site, doc, notes)
