"""Building configuration of the virtual building (pydantic), read from ``configs/buildings``."""

from __future__ import annotations

import datetime as dt
from pathlib import Path
from typing import Literal
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

import yaml
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

Layer = tuple[str, float, float, float, float] | tuple[str, float]

CONFIG_DIR = Path(__file__).resolve().parent.parent / "configs" / "buildings"


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class Location(_Strict):
    latitude: float = Field(ge=-90, le=90)
    longitude: float = Field(ge=-180, le=180)
    elevation: float = 0.0
    timezone: str

    @field_validator("timezone")
    @classmethod
    def _known_zone(cls, v):
        try:
            ZoneInfo(v)
        except (ZoneInfoNotFoundError, ValueError):
            raise ValueError(f"timezone {v!r} is not an IANA time zone; write e.g. "
                             "America/Los_Angeles") from None
        return v

    @property
    def standard_offset_hours(self) -> float:
        """UTC offset of the local standard (winter) time [h], e.g. -8 for Los Angeles."""
        jan = dt.datetime(2015, 1, 15, tzinfo=ZoneInfo(self.timezone))
        return jan.utcoffset().total_seconds() / 3600.0


class Glazing(_Strict):
    u_factor: float = Field(gt=0, description="[W/(m2 K)]")
    shgc: float = Field(gt=0, lt=1)
    visible_transmittance: float = Field(gt=0, lt=1)


class ExteriorShading(_Strict):
    """Overhangs and fins on every exterior window."""

    overhang_depth_ratio: float = Field(0.0, ge=0, le=3, description="[-] overhang depth as a "
                                        "fraction of the window height "
                                        "(Shading:Overhang:Projection); 0: no overhang")
    overhang_offset: float = Field(0.0, ge=0, description="[m] overhang above the window top")
    fin_depth: float = Field(0.0, ge=0, description="[m] depth of a fin at each end of the "
                             "window, as high as the window (Shading:Fin); 0: no fins")


class ReturnPlenum(_Strict):
    """A return plenum above the rooms: one unconditioned zone over the whole floor that
    every box's return air flows through."""

    height: float = Field(gt=0, le=2, description="[m] between the rooms' ceilings (acoustic "
                          "tile) and the slab or roof above")
    lights_return_fraction: float = Field(0.0, ge=0, le=0.5, description="[-] share of the "
                                          "lights' heat released into the return air "
                                          "(Lights Return Air Fraction)")


class Room(_Strict):
    rect: tuple[float, float, float, float]
    zone: str
    kind: str
    windows: bool
    box_shares: tuple[float, ...] = Field(
        (1.0,), description="[-] shares of the room's design airflow, one per VAV box "
        "serving it (an open-plan room often has several)")

    @field_validator("rect")
    @classmethod
    def _ordered(cls, v):
        if not (v[2] > v[0] and v[3] > v[1]):
            raise ValueError(f"rect {v} must be [x0, y0, x1, y1] with x1 > x0 and y1 > y0")
        return v

    @field_validator("box_shares")
    @classmethod
    def _shares(cls, v):
        if not v or min(v) <= 0 or abs(sum(v) - 1.0) > 1e-6:
            raise ValueError(f"box_shares {v} must be positive and sum to 1 (one per box)")
        return v

    @property
    def floor_area(self) -> float:
        x0, y0, x1, y1 = self.rect
        return (x1 - x0) * (y1 - y0)


class Kind(_Strict):
    people_per_m2: float = Field(ge=0)
    lights_w_m2: float = Field(ge=0)
    equipment_w_m2: float = Field(ge=0)
    equipment_base: float = Field(ge=0, le=1)
    occupancy: Literal["office", "transit", "none"]


class Setpoints(_Strict):
    occupied: float
    unoccupied: float


class Hvac(_Strict):
    design_airflow_perimeter: float = Field(gt=0)
    design_airflow_core: float = Field(gt=0)
    minimum_fraction: float = Field(gt=0, le=1)
    reheat_max_fraction: float = Field(gt=0, le=1)
    supply_setpoint: float
    supply_reset: tuple[float, float, float, float]
    heating: Setpoints
    cooling: Setpoints
    occupied_hours: tuple[int, int]
    experiment_heating: float
    experiment_cooling: float


class Campaign(_Strict):
    """Simulated weeks and excitation experiments.

    Attributes
    ----------
    weeks : Mondays of the simulated weeks.
    excitation_weekends : Saturdays whose weekend runs the excitation experiment.
    excitation_days : ``"weekend"`` excites Saturday and Sunday (the paper's campaign),
        ``"saturday"`` Saturday only.
    """

    weeks: list[dt.date]
    excitation_weekends: list[dt.date]
    excitation_days: Literal["weekend", "saturday"] = "weekend"

    @property
    def excitation_offsets(self) -> tuple[int, ...]:
        """Days after each excitation Saturday that are excited (0 = Saturday)."""
        return (0, 1) if self.excitation_days == "weekend" else (0,)

    @model_validator(mode="after")
    def _check(self):
        for w in self.weeks:
            if w.weekday() != 0:
                raise ValueError(f"campaign week {w} must start on a Monday")
        for d in self.excitation_weekends:
            if d.weekday() != 5:
                raise ValueError(f"excitation weekend {d} must be a Saturday")
            if not any(w <= d < w + dt.timedelta(days=7) for w in self.weeks):
                raise ValueError(f"excitation weekend {d} lies in none of the campaign weeks")
        return self


class BuildingConfig(_Strict):
    name: str
    location: Location
    weather: str
    floor_to_ceiling: float = Field(gt=0)
    window_to_wall_ratio: float = Field(ge=0, lt=0.95)
    glazing: Glazing
    rooms: dict[str, Room]
    kinds: dict[str, Kind]
    constructions: dict[str, list[Layer]]
    furniture_area_per_floor_area: float = Field(ge=0)
    hvac: Hvac
    infiltration_m3s_per_m2_facade: float = Field(ge=0)
    campaign: Campaign
    north_axis: float = Field(0.0, ge=0, lt=360, description="[deg] clockwise rotation of the "
                              "plan's y axis from true north (EnergyPlus Building North Axis)")
    weekend_occupancy: float = Field(0.0, ge=0, le=1, description="[-] chance that a person "
                                     "works a full day on a weekend day, as a fraction of the "
                                     "weekday chance (0: only short weekend visits)")
    floor_position: Literal["middle", "top", "ground"] = Field(
        "middle", description="middle: floor and ceiling adiabatic (conditioned floors above "
                              "and below); top: the ceilings are a roof (construction 'roof'); "
                              "ground: the floors lie on the ground (boundary Ground at "
                              "ground_temperature)")
    shading: ExteriorShading | None = Field(None, description="overhangs and fins on the "
                                            "exterior windows; None: no exterior shading")
    plenum: ReturnPlenum | None = Field(None, description="return plenum above the rooms; "
                                        "None: the ceilings are the slab (no plenum)")
    ground_temperature: list[float] | None = Field(
        None, min_length=12, max_length=12,
        description="[degC] temperature under a ground floor, January to December "
                    "(Site:GroundTemperature:BuildingSurface); needed by floor_position ground")

    @model_validator(mode="after")
    def _refs(self):
        for name, room in self.rooms.items():
            if room.kind not in self.kinds:
                raise ValueError(f"room {name}: kind {room.kind!r} is not in kinds {sorted(self.kinds)}")
        need = {"exterior_wall", "interior_wall", "floor", "ceiling", "furniture"}
        if self.floor_position == "top":
            need.add("roof")
        if self.floor_position == "ground" and self.ground_temperature is None:
            raise ValueError("floor_position ground needs ground_temperature (12 monthly degC)")
        if missing := need - set(self.constructions):
            raise ValueError(f"constructions lacks {sorted(missing)}")
        return self

    @property
    def zones(self) -> dict[str, list[str]]:
        out: dict[str, list[str]] = {}
        for name, room in self.rooms.items():
            out.setdefault(room.zone, []).append(name)
        return out


def load_config(name_or_path: str | Path = "office6") -> BuildingConfig:
    """Load a building config by name (from ``configs/buildings``) or path."""
    path = Path(name_or_path)
    if not path.suffix:
        path = CONFIG_DIR / f"{name_or_path}.yaml"
    if not path.is_file():
        raise FileNotFoundError(f"building config {path} not found; names in {CONFIG_DIR}: "
                                f"{sorted(p.stem for p in CONFIG_DIR.glob('*.yaml'))}")
    with open(path, encoding="utf-8") as fh:
        return BuildingConfig.model_validate(yaml.safe_load(fh))
