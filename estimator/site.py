"""The site description: the input contract every real site must be able to fill.

A site description (``site.yaml``) names the building's EnergyPlus input file, groups
EnergyPlus zones (rooms) into model zones, lists the VAV boxes with the room each
serves and the telemetry point measuring its airflow, and maps telemetry columns to
the model's roles (zone temperatures, supply air temperature, outdoor air temperature,
weather-station solar irradiance), each with its unit. See docs/data.md.
"""

from __future__ import annotations

import datetime as dt
import re
from pathlib import Path
from typing import ClassVar
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

import numpy as np
import pandas as pd
import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator
from zonecast.estimator.units import check_unit

SITE_SCHEMA_VERSION = 1


class SiteError(ValueError):
    """A site description is invalid; the message says which field and how to fix it."""


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class Point(_Strict):
    """A telemetry column and its unit."""
    point: str = Field(min_length=1, description="telemetry column name")
    unit: str


def _point(v, default_unit: str):
    if isinstance(v, str):
        return {"point": v, "unit": default_unit}
    return v


class _QuantityPoint(Point):
    """A point whose unit must measure ``quantity``."""
    quantity: ClassVar[str]

    @field_validator("unit")
    @classmethod
    def _unit(cls, v):
        return check_unit(v, cls.quantity)


class TemperaturePoint(_QuantityPoint):
    quantity: ClassVar[str] = "temperature"
    unit: str = "degC"


class AirflowPoint(_QuantityPoint):
    quantity: ClassVar[str] = "airflow"
    unit: str = "kg/s"


class IrradiancePoint(_QuantityPoint):
    quantity: ClassVar[str] = "irradiance"
    unit: str = "W/m2"


class PowerPoint(_QuantityPoint):
    quantity: ClassVar[str] = "power"
    unit: str = "W"


class CloudCoverPoint(_QuantityPoint):
    """The share of the sky covered by opaque cloud: a fraction (``1``), ``%``, ``okta``
    or ``tenths``."""
    quantity: ClassVar[str] = "cloud_cover"
    unit: str = "1"


class Box(_Strict):
    """A VAV box: the room (EnergyPlus zone) it serves, its airflow point and, optionally,
    its discharge-air temperature point (the air leaving the box, after any reheat coil).

    With a discharge-air point the model takes the heat a box delivers as
    c_p u (T_discharge - T_room) instead of c_p u (T_supply - T_room): reheat becomes a
    measured input rather than part of the unknown internal gains (docs/model.md).
    """
    room: str
    airflow: AirflowPoint
    discharge_temperature: TemperaturePoint | None = None

    @field_validator("airflow", mode="before")
    @classmethod
    def _short(cls, v):
        return _point(v, "kg/s")

    @field_validator("discharge_temperature", mode="before")
    @classmethod
    def _short_t(cls, v):
        return None if v is None else _point(v, "degC")


class Solar(_Strict):
    """Weather-station irradiance on the horizontal (GHI, DHI) and normal to the sun (DNI)."""
    global_horizontal: IrradiancePoint
    direct_normal: IrradiancePoint
    diffuse_horizontal: IrradiancePoint

    @field_validator("*", mode="before")
    @classmethod
    def _short(cls, v):
        return _point(v, "W/m2")


def _zone_points(v, field: str, what: str, unit: str) -> dict:
    """A map of model zones to one point or a list of points (short forms in ``unit``)."""
    if not isinstance(v, dict):
        # pydantic turns only ValueError into a ValidationError with the field's location
        msg = f"{field} must map each model zone to a point or a list of points"
        raise ValueError(msg)  # noqa: TRY004
    out = {}
    for zone, pts in v.items():
        pts = pts if isinstance(pts, list) else [pts]
        if not pts:
            raise ValueError(f"{field}[{zone}] lists no {what}")
        out[zone] = [_point(p, unit) for p in pts]
    return out


class ZoneSensor(TemperaturePoint):
    """A temperature sensor of a model zone, optionally naming the room it sits in."""
    room: str | None = None


class Points(_Strict):
    """Telemetry columns by role. Zone temperature: one or more sensors per model zone.

    ``power`` (optional): model zone -> electricity meters [W] of the lights and plug loads
    of the zone's rooms (sub-meters of the lighting and receptacle panels); a zone's
    meters are summed. Electric power in a room ends as heat in it, so where the site has
    them the identification takes the weekends' metered rise as the shape of their
    internal gains (docs/identification.md "Metered weekend gains").

    ``cloud_cover`` (optional): the opaque cloud cover of the sky over the site (a weather
    station's or a weather service's reading, e.g. METAR oktas or Open-Meteo's
    ``cloud_cover`` in %): with it the model's long-wave exchange with the sky uses a
    cloudy sky's temperature (``ModelOptions.sky``, docs/model.md "Sky").
    """
    zone_temperature: dict[str, list[ZoneSensor]]
    supply_air_temperature: TemperaturePoint
    outdoor_air_temperature: TemperaturePoint
    solar: Solar
    power: dict[str, list[PowerPoint]] = Field(default_factory=dict)
    cloud_cover: CloudCoverPoint | None = None

    @field_validator("cloud_cover", mode="before")
    @classmethod
    def _cloud(cls, v):
        return None if v is None else _point(v, "1")

    @field_validator("power", mode="before")
    @classmethod
    def _power(cls, v):
        return {} if v is None else _zone_points(v, "power", "meter", "W")

    @field_validator("zone_temperature", mode="before")
    @classmethod
    def _zones(cls, v):
        return _zone_points(v, "zone_temperature", "sensor", "degC")

    @field_validator("supply_air_temperature", "outdoor_air_temperature", mode="before")
    @classmethod
    def _short(cls, v):
        return _point(v, "degC")


class Location(_Strict):
    latitude: float = Field(ge=-90, le=90, description="[deg north]")
    longitude: float = Field(ge=-180, le=180, description="[deg east]")
    elevation: float = Field(0.0, description="[m]")


class Experiment(_Strict):
    """A period of excitation experiments (paper section 2-B)."""
    start: dt.datetime
    end: dt.datetime
    kind: str = "excitation"

    @model_validator(mode="after")
    def _check(self):
        if self.start.tzinfo is None or self.end.tzinfo is None:
            raise ValueError("experiment start and end need a UTC offset, e.g. "
                             "2015-04-18T08:00:00-07:00")
        if self.end <= self.start:
            raise ValueError(f"experiment end {self.end} is not after its start {self.start}")
        return self


class Thermostat(_Strict):
    """The zones' thermostat schedule (optional; the diagnosis's scheduled reheat term
    uses it, docs/diagnosis.md). Set points [degC]; occupied hours are local wall-clock
    hours [start, end) on the working days (0 = Monday)."""
    heating_occupied: float = Field(ge=0, le=40)
    heating_unoccupied: float = Field(ge=0, le=40)
    cooling_occupied: float | None = Field(None, ge=0, le=50)
    cooling_unoccupied: float | None = Field(None, ge=0, le=50)
    occupied_hours: tuple[float, float] = (7.0, 19.0)
    working_days: list[int] = Field(default_factory=lambda: [0, 1, 2, 3, 4])
    holidays: list[dt.date] = Field(
        default_factory=list, description="local dates that are not working days (the "
        "served forecast's HVAC-input learner treats them as weekend days)")
    experiment_heating: float | None = Field(
        None, ge=0, le=40, description="heating set point during the site's experiments")

    @model_validator(mode="after")
    def _check(self):
        h0, h1 = self.occupied_hours
        if not 0 <= h0 < h1 <= 24:
            raise ValueError(f"thermostat occupied_hours {self.occupied_hours}: need "
                             "0 <= start < end <= 24 (local hours)")
        bad = [d for d in self.working_days if d not in range(7)]
        if bad:
            raise ValueError(f"thermostat working_days {bad}: use 0 (Monday) to 6 (Sunday)")
        return self

    def heating_setpoint(self, times, timezone: str, experiment=None):
        """Scheduled heating set point at each time [degC], shape (N,); ``experiment``
        (N,) bool marks rows of experiments (they take ``experiment_heating`` if given)."""
        occ = self.occupied(times, timezone)
        out = np.where(occ, self.heating_occupied, self.heating_unoccupied).astype(float)
        if experiment is not None and self.experiment_heating is not None:
            out[np.asarray(experiment, bool)] = self.experiment_heating
        return out

    def occupied(self, times, timezone: str) -> np.ndarray:
        """Whether each time lies in the occupied hours of a working day that is not a
        holiday (N,) bool."""
        local = pd.DatetimeIndex(times).tz_convert(timezone)
        hour = np.asarray(local.hour + local.minute / 60.0)
        h0, h1 = self.occupied_hours
        occ = np.isin(np.asarray(local.day_of_week), self.working_days) & (hour >= h0) \
            & (hour < h1)
        if self.holidays:
            occ &= ~np.isin(np.asarray(local.date), np.array(self.holidays))
        return occ

    def band(self, times, timezone: str, experiment=None) -> tuple[np.ndarray, np.ndarray]:
        """Scheduled heating and cooling set points at each time [degC], two (N,) arrays:
        the band a zone's controllers hold the room air in while they have the capacity.
        Where a set point is not declared, and in experiments (``experiment`` (N,) bool;
        their set points are widened), the band is open (-inf or +inf)."""
        heat = self.heating_setpoint(times, timezone)
        cool = np.full(len(heat), np.inf)
        if self.cooling_occupied is not None and self.cooling_unoccupied is not None:
            cool = np.where(self.occupied(times, timezone), self.cooling_occupied,
                            self.cooling_unoccupied).astype(float)
        if experiment is not None:
            exp = np.asarray(experiment, bool)
            heat[exp], cool[exp] = -np.inf, np.inf
        return heat, cool


_STEP = re.compile(r"^\s*(\d+)\s*(s|sec|min|h)\s*$")


def parse_step(v) -> dt.timedelta:
    """'15min', '900s', '1h' or a timedelta -> timedelta."""
    if isinstance(v, dt.timedelta):
        return v
    m = _STEP.match(str(v))
    if not m:
        raise ValueError(f"step {v!r}: write e.g. '15min', '900s' or '1h'")
    n, u = int(m.group(1)), m.group(2)
    return dt.timedelta(seconds=n * {"s": 1, "sec": 1, "min": 60, "h": 3600}[u])


class Site(_Strict):
    """A site description (see docs/data.md).

    Attributes
    ----------
    building : identifier of the building (letters, digits, ``-`` and ``_``).
    idf : the building's EnergyPlus input file, relative to the site file.
    timezone : IANA time zone; schedules and time-of-week use local time.
    location : latitude, longitude [deg] and elevation [m].
    step : the model step (15 min in the paper).
    zones : model zone -> EnergyPlus zone names (rooms).
    boxes : VAV box id -> room served, airflow point and optional discharge-air point.
    points : telemetry columns by role, with units.
    experiments : excitation experiment periods, if any.
    thermostat : the zones' set point schedule, if known.
    weather_file : the EPW weather file the building's EnergyPlus input is simulated with,
        relative to the site file, if any: its ground temperatures are what EnergyPlus puts
        under F- and C-factor floors and walls (docs/data.md).
    """

    schema_version: int = SITE_SCHEMA_VERSION
    building: str = Field(pattern=r"^[A-Za-z0-9_-]+$")
    idf: Path
    timezone: str
    location: Location
    step: dt.timedelta = dt.timedelta(minutes=15)
    zones: dict[str, list[str]]
    boxes: dict[str, Box]
    points: Points
    experiments: list[Experiment] = Field(default_factory=list)
    thermostat: Thermostat | None = None
    weather_file: Path | None = None
    base_dir: Path | None = Field(None, exclude=True)

    @field_validator("step", mode="before")
    @classmethod
    def _step(cls, v):
        return parse_step(v)

    @field_validator("timezone")
    @classmethod
    def _tz(cls, v):
        try:
            ZoneInfo(v)
        except (ZoneInfoNotFoundError, ValueError):
            raise ValueError(f"timezone {v!r} is not an IANA time zone (e.g. America/Los_Angeles)")
        return v

    @model_validator(mode="after")
    def _consistent(self):
        if self.step <= dt.timedelta(0) or (86400 % self.step.total_seconds()):
            raise ValueError(f"step {self.step} must divide a day")
        if not self.zones:
            raise ValueError("zones: name at least one model zone")
        rooms: dict[str, str] = {}
        for zone, members in self.zones.items():
            if not members:
                raise ValueError(f"zones[{zone}] lists no EnergyPlus zone")
            for r in members:
                if r.upper() in rooms:
                    raise ValueError(f"room {r} is in model zones {rooms[r.upper()]} and {zone}; "
                                     "a room belongs to one model zone")
                rooms[r.upper()] = zone
        for box, spec in self.boxes.items():
            if spec.room.upper() not in rooms:
                raise ValueError(f"boxes[{box}].room {spec.room!r} is in no model zone; rooms "
                                 f"are {sorted(rooms)}")
        tz_zones = set(self.points.zone_temperature)
        if tz_zones != set(self.zones):
            raise ValueError("points.zone_temperature must name exactly the model zones "
                             f"{sorted(self.zones)}; it names {sorted(tz_zones)}")
        extra = sorted(set(self.points.power) - set(self.zones))
        if extra:
            raise ValueError(f"points.power names {extra}, which are not model zones "
                             f"{sorted(self.zones)}")
        for zone, sensors in self.points.zone_temperature.items():
            for s in sensors:
                if s.room is not None and rooms.get(s.room.upper()) != zone:
                    raise ValueError(f"points.zone_temperature[{zone}]: sensor {s.point} sits in "
                                     f"room {s.room}, which is not in model zone {zone}")
        cols = self.point_units()
        if len(cols) != len(self._all_points()):
            dup = sorted({p.point for p in self._all_points()
                          if sum(q.point == p.point for q in self._all_points()) > 1})
            raise ValueError(f"points {dup} are mapped to more than one role")
        return self

    def _all_points(self) -> list[Point]:
        p = self.points
        pts: list[Point] = [s for ss in p.zone_temperature.values() for s in ss]
        pts += [p.supply_air_temperature, p.outdoor_air_temperature, p.solar.global_horizontal,
                p.solar.direct_normal, p.solar.diffuse_horizontal]
        pts += [b.airflow for b in self.boxes.values()]
        pts += [b.discharge_temperature for b in self.boxes.values()
                if b.discharge_temperature is not None]
        pts += [m for ms in p.power.values() for m in ms]
        if p.cloud_cover is not None:
            pts.append(p.cloud_cover)
        return pts

    def point_units(self) -> dict[str, str]:
        """Every telemetry column the site needs -> its unit."""
        return {p.point: p.unit for p in self._all_points()}

    def meter_points(self) -> list[str]:
        """The lights and plug-load meters' columns (``points.power``): used by the
        identification, not by the state estimator."""
        return [m.point for ms in self.points.power.values() for m in ms]

    @property
    def zone_names(self) -> list[str]:
        return list(self.zones)

    @property
    def tz(self) -> ZoneInfo:
        return ZoneInfo(self.timezone)

    @property
    def idf_path(self) -> Path:
        return self.idf if self.idf.is_absolute() or self.base_dir is None else self.base_dir / self.idf

    @property
    def weather_path(self) -> Path | None:
        """The weather file's path (None if the site names none)."""
        w = self.weather_file
        if w is None:
            return None
        return w if w.is_absolute() or self.base_dir is None else self.base_dir / w

    def to_yaml(self, path: str | Path) -> None:
        data = self.model_dump(mode="json", exclude={"base_dir"})
        data["step"] = f"{int(self.step.total_seconds() // 60)}min"
        with open(path, "w", encoding="utf-8") as fh:
            yaml.safe_dump(data, fh, sort_keys=False, allow_unicode=True)


def _format_errors(err: ValidationError, source: str) -> str:
    lines = [f"{source} is not a valid site description:"]
    for e in err.errors():
        loc = ".".join(str(p) for p in e["loc"]) or "(top level)"
        lines.append(f"  - {loc}: {e['msg']}")
    return "\n".join(lines)


def load_site(path: str | Path) -> Site:
    """Read and validate ``site.yaml``; errors name the field and say what to fix."""
    path = Path(path)
    if not path.is_file():
        raise SiteError(f"site description {path} not found")
    try:
        with open(path, encoding="utf-8") as fh:
            data = yaml.safe_load(fh)
    except yaml.YAMLError as exc:
        raise SiteError(f"{path} is not valid YAML: {exc}") from None
    if not isinstance(data, dict):
        raise SiteError(f"{path} must hold a mapping of fields (building, idf, zones, ...)")
    try:
        return Site.model_validate({**data, "base_dir": path.parent.resolve()})
    except ValidationError as err:
        raise SiteError(_format_errors(err, str(path))) from None
