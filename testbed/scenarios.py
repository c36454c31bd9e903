"""Blind-diagnosis scenarios for any building of the family (``benchmarks/bench_diagnose.py``).

A scenario is one campaign of the virtual building with one effect the identified model lacks
switched on (testbed switches, :mod:`.effects`), or a control with nothing added. Office6 has
its own hand-written list in the benchmark; for any other building the list is built here from
the building's own zones, with the same effect kinds and magnitudes comparable to office6's.
The zone an effect is put in is drawn with ``numpy.random.default_rng([seed, kind])`` from the
building's zones, so the list depends only on the building and the scenario seeds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: effect kinds in a fixed order (their position seeds the zone draw)
KINDS = ("reheat", "infiltration", "sensor_bias", "window_solar", "supply_offset",
         "occupancy_gains", "thermal_mass", "interzone_air")

#: (kind, scenario seed, magnitude): two scenarios per kind, magnitudes from office6's list
#: (infiltration scale, bias [K], SHGC scale of the building's own, supply offset [K], gains
#: scale, furniture-area scale, mixing flow [m3/s])
PLAN = (
    ("reheat", 1, None), ("reheat", 2, None),
    ("infiltration", 1, 2.0), ("infiltration", 3, 1.5),
    ("sensor_bias", 1, 0.5), ("sensor_bias", 2, -0.4),
    ("window_solar", 2, 1.75), ("window_solar", 3, 0.4),
    ("supply_offset", 1, 1.0), ("supply_offset", 2, -1.5),
    ("occupancy_gains", 2, 1.5), ("occupancy_gains", 3, 0.5),
    ("thermal_mass", 1, 3.0), ("thermal_mass", 2, 4.0),
    ("interzone_air", 3, 0.1), ("interzone_air", 1, 0.05),
)
CONTROL_SEEDS = (1, 2, 3)


@dataclass(frozen=True)
class Scenario:
    """One campaign of the benchmark.

    Attributes
    ----------
    name : folder name, e.g. ``bias_E_+0.5_s1``.
    seed : campaign seed (occupancy, excitation order, sensor noise).
    switches : testbed options on top of the control's (``["reheat"]`` turns reheat on).
    truth : the effect switched on (the diagnosis library's name), None for a control.
    """

    name: str
    seed: int
    switches: tuple[str, ...]
    truth: str | None

    def as_tuple(self) -> tuple:
        return self.name, self.seed, list(self.switches), self.truth


def pick_zone(zones: list[str], seed: int, kind: str) -> str:
    """The zone of ``zones`` that scenario ``(kind, seed)`` puts its effect in."""
    if not zones:
        raise ValueError("the building has no zones to put an effect in")
    rng = np.random.default_rng([seed, KINDS.index(kind)])
    return zones[int(rng.integers(len(zones)))]


def _num(x: float) -> str:
    return f"{x:g}"


def member_scenarios(zones: list[str], shgc: float, furniture: float) -> list[Scenario]:
    """Controls and one-effect scenarios for a building with model zones ``zones``, window
    SHGC ``shgc`` [-] and furniture area per floor area ``furniture`` [-].

    Thermal-mass scenarios scale the furniture and are left out when the building has none
    (the switch would change nothing). SHGC scenarios scale the building's own SHGC (kept in
    0.05–0.85).
    """
    if not 0 < shgc < 1:
        raise ValueError(f"SHGC {shgc} must be in (0, 1)")
    out = [Scenario(f"control_s{s}", s, (), None) for s in CONTROL_SEEDS]
    for kind, seed, mag in PLAN:
        if kind == "reheat":
            out.append(Scenario(f"reheat_s{seed}", seed, ("reheat",), kind))
        elif kind == "infiltration":
            out.append(Scenario(f"infiltration_x{_num(mag)}_s{seed}", seed,
                                ("--set", f"infiltration={_num(mag)}"), kind))
        elif kind == "window_solar":
            value = round(float(np.clip(shgc * mag, 0.05, 0.85)), 2)
            out.append(Scenario(f"shgc_{_num(value)}_s{seed}", seed,
                                ("--set", f"shgc={_num(value)}"), kind))
        elif kind == "supply_offset":
            out.append(Scenario(f"supply_offset_{mag:+g}_s{seed}", seed,
                                ("--set", f"supply_offset={_num(mag)}"), kind))
        elif kind == "thermal_mass" and furniture <= 0:
            continue
        else:
            zone = pick_zone(zones, seed, kind)
            key, label = {"sensor_bias": ("bias", f"{mag:+g}"),
                          "occupancy_gains": ("gains", f"x{_num(mag)}"),
                          "thermal_mass": ("mass", f"x{_num(mag)}"),
                          "interzone_air": ("mixing", _num(mag))}[kind]
            out.append(Scenario(f"{key}_{zone}_{label}_s{seed}", seed,
                                ("--set", f"{key}.{zone}={_num(mag)}"), kind))
    return out
