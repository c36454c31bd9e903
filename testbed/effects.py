"""Effect switches of the virtual building.

They exist so that later work can withhold an effect from a model and check that the
diagnosis finds it. Each switch and what it changes is listed in docs/testbed.md.
"""

from __future__ import annotations

from typing import Literal, get_args

from pydantic import BaseModel, ConfigDict, Field

EFFECTS = ("reheat", "infiltration", "gains", "window_solar", "sensor_noise", "sensor_bias",
           "supply_offset", "discharge_sensors", "power_meters")


class Effects(BaseModel):
    """What the virtual building simulates and how its sensors read.

    Attributes
    ----------
    reheat : VAV box reheat coils available (False: their availability schedule is off).
    infiltration : scale of the design infiltration flow [-] (0 disables it).
    gains : per model zone scale of people, lights and equipment design levels [-].
    shgc : window solar heat gain coefficient [-], None keeps the building config's.
    sensor_noise : standard deviation of zone temperature sensor noise [degC].
    sensor_resolution : temperature sensor resolution [degC] (readings are rounded).
    sensor_bias : per model zone additive temperature sensor bias [degC].
    airflow_noise : relative standard deviation of box airflow readings [-].
    supply_offset : the supply air reaching the boxes is this much warmer than the AHU
        supply temperature sensor reads (the sensor reads true minus it) [degC].
    mass : per model zone scale of the furniture (internal mass) area [-].
    mixing : per model zone air flow exchanged both ways between each of its rooms and
        each neighbouring room of another zone (open doors, transfer grilles) [m3/s].
    discharge_sensors : the VAV boxes report their discharge-air temperature (a telemetry
        point per box in the site description); False: a BMS without them, where reheat
        is an effect the model does not see.
    power_meters : each model zone's lights and plug loads are sub-metered (a telemetry
        point ``P_<zone>`` [W] per zone under ``points.power`` of the site description).
    sky : the sky temperature of every exterior face's long-wave exchange: ``"weather"``,
        EnergyPlus's own (from the weather file's horizontal infrared), or ``"dry_bulb"``,
        the outdoor air temperature (``WeatherProperty:SkyTemperature``), a building without
        the sky's long-wave deficit: what a model with that physics exactly right would see.
    inside_convection : EnergyPlus's inside convection algorithm: ``"tarp"`` (its default,
        natural convection whose coefficient follows the face-air temperature difference
        and the heat flow's direction; nothing written to the file) or ``"simple"``
        (``SurfaceConvectionAlgorithm:Inside, Simple``: a constant coefficient per face
        orientation and, for horizontal faces, direction of the heat flow: 4.04 / 0.95
        W/m2K; benchmarks/bench_convection_regimes.py), films of a constant size. The
        generated floors only: ``testbed foreign`` keeps the file's own algorithm.
    """

    model_config = ConfigDict(extra="forbid")
    reheat: bool = True
    infiltration: float = Field(1.0, ge=0)
    gains: dict[str, float] = Field(default_factory=dict)
    shgc: float | None = Field(None, gt=0, lt=1)
    sensor_noise: float = Field(0.1, ge=0)
    sensor_resolution: float = Field(0.1, ge=0)
    sensor_bias: dict[str, float] = Field(default_factory=dict)
    airflow_noise: float = Field(0.0, ge=0)
    supply_offset: float = Field(0.0, ge=-5, le=5)
    mass: dict[str, float] = Field(default_factory=dict)
    mixing: dict[str, float] = Field(default_factory=dict)
    discharge_sensors: bool = True
    power_meters: bool = True
    sky: Literal["weather", "dry_bulb"] = "weather"
    inside_convection: Literal["tarp", "simple"] = "tarp"

    def gain_scale(self, zone: str) -> float:
        return self.gains.get(zone, 1.0)

    def mass_scale(self, zone: str) -> float:
        return self.mass.get(zone, 1.0)


def _num(key: str, value: str) -> float:
    try:
        return float(value)
    except ValueError:
        raise ValueError(f"--set {key}={value}: the value must be a number") from None


def parse_switches(disable: list[str] | None, set_: list[str] | None, zones: list[str]) -> Effects:
    """Turn ``--disable EFFECT`` and ``--set EFFECT=VALUE`` options into :class:`Effects`.

    ``EFFECT`` is one of reheat, infiltration, gains[.ZONE], window_solar,
    sensor_noise, sensor_bias, supply_offset; ``--set`` also takes shgc, sensor_resolution,
    airflow_noise, sky (``weather`` or ``dry_bulb``), inside_convection (``tarp`` or
    ``simple``), bias.ZONE, mass.ZONE and mixing.ZONE.
    """
    data: dict = {"gains": {}, "sensor_bias": {}, "mass": {}, "mixing": {}}

    def zone_of(key: str) -> str:
        zone = key.split(".", 1)[1]
        if zone not in zones:
            raise ValueError(f"{key}: unknown model zone {zone!r}; zones are {zones}")
        return zone

    for item in disable or []:
        if item == "reheat":
            data["reheat"] = False
        elif item == "infiltration":
            data["infiltration"] = 0.0
        elif item == "gains":
            data["gains"] = {z: 0.0 for z in zones}
        elif item.startswith("gains."):
            data["gains"][zone_of(item)] = 0.0
        elif item == "window_solar":
            data["shgc"] = 0.01
        elif item == "sensor_noise":
            data["sensor_noise"] = 0.0
            data["sensor_resolution"] = 0.0
        elif item == "sensor_bias":
            data["sensor_bias"] = {}
        elif item == "supply_offset":
            data["supply_offset"] = 0.0
        elif item == "discharge_sensors":
            data["discharge_sensors"] = False
        elif item == "power_meters":
            data["power_meters"] = False
        else:
            raise ValueError(f"--disable {item}: unknown effect; choose from {list(EFFECTS)} "
                             f"or gains.ZONE")
    for item in set_ or []:
        if "=" not in item:
            raise ValueError(f"--set {item}: write EFFECT=VALUE, e.g. infiltration=2.0")
        key, value = item.split("=", 1)
        if key in ("infiltration", "shgc", "sensor_noise", "sensor_resolution", "airflow_noise",
                   "supply_offset"):
            data[key] = _num(key, value)
        elif key == "reheat":
            data["reheat"] = value.lower() in ("1", "true", "on", "yes")
        elif key == "sky":
            if value not in get_args(Effects.model_fields["sky"].annotation):
                raise ValueError(f"--set sky={value}: choose 'weather' (EnergyPlus's sky from "
                                 "the weather file) or 'dry_bulb' (the sky at the outdoor air)")
            data["sky"] = value
        elif key == "inside_convection":
            if value not in get_args(Effects.model_fields["inside_convection"].annotation):
                raise ValueError(f"--set inside_convection={value}: choose 'tarp' "
                                 "(EnergyPlus's default) or 'simple' (constant films)")
            data["inside_convection"] = value
        elif key.startswith("gains."):
            data["gains"][zone_of(key)] = _num(key, value)
        elif key.startswith("bias."):
            data["sensor_bias"][zone_of(key)] = _num(key, value)
        elif key.startswith("mass."):
            scale = _num(key, value)
            if not scale > 0:
                raise ValueError(f"--set {key}={value}: the furniture area scale must be > 0")
            data["mass"][zone_of(key)] = scale
        elif key.startswith("mixing."):
            flow = _num(key, value)
            if not flow >= 0:
                raise ValueError(f"--set {key}={value}: the mixing flow must be >= 0 [m3/s]")
            data["mixing"][zone_of(key)] = flow
        else:
            raise ValueError(f"--set {key}: unknown setting; choose from infiltration, shgc, "
                             "sensor_noise, sensor_resolution, airflow_noise, supply_offset, "
                             "reheat, sky, gains.ZONE, bias.ZONE, mass.ZONE, mixing.ZONE")
    return Effects.model_validate(data)
