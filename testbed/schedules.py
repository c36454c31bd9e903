"""Seeded schedules of the virtual building: occupancy, lights, equipment, VAV box
minimum-flow fractions, thermostat set points and the paper's excitation experiments.

All schedules are 15-min series on the local wall clock (EnergyPlus shifts schedules
with daylight saving time). The paper's internal gains are its central difficulty, so
occupancy differs from day to day: each person is absent on some days, arrives and
leaves at random times and sometimes goes out for lunch.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass

import numpy as np
import pandas as pd
from zonecast.testbed.config import BuildingConfig

STEPS_PER_DAY = 96
STEP = dt.timedelta(minutes=15)


def rng_for(seed: int, purpose: str) -> np.random.Generator:
    """Independent generator per purpose, so a change in one never shifts another."""
    tag = {"occupancy": 1, "excitation": 2, "noise": 3, "meters": 4}[purpose]
    return np.random.default_rng([int(seed), tag])


def _hours(n_days: int) -> np.ndarray:
    return (np.arange(STEPS_PER_DAY) + 0.5) * 0.25  # interval mid-points [h]


def office_occupancy(days: pd.DatetimeIndex, n_people: int, rng: np.random.Generator,
                     weekend_work: float = 0.0) -> np.ndarray:
    """Fraction of a room's people present, (n_days, 96).

    Working days: each person is present with probability 0.85, arrives ~N(8.75 h, 0.75 h),
    leaves ~N(17.5 h, 1 h) and is out for lunch (12-13 h) half of the time. Weekends:
    each person comes in with probability 0.12 for 2-6 hours from ~N(11 h, 1.5 h); with
    ``weekend_work`` > 0 each person also works a full day with probability
    ``weekend_work`` * 0.85, arriving ~N(9.5 h, 1 h) and leaving ~N(16.5 h, 1 h).

    Parameters
    ----------
    days : the local dates of the rows.
    n_people : people of the room (at least one is simulated).
    rng : the occupancy generator; ``weekend_work`` = 0 draws exactly what it always drew.
    weekend_work : [-] weekend chance of a full working day as a fraction of the weekday's.
    """
    n_days = len(days)
    n = max(n_people, 1)
    h = _hours(n_days)[None, None, :]
    weekend = (days.day_of_week >= 5)[:, None, None]
    present = rng.random((n_days, n, 1)) < np.where(weekend, 0.12, 0.85)
    arrive = np.where(weekend, rng.normal(11.0, 1.5, (n_days, n, 1)),
                      rng.normal(8.75, 0.75, (n_days, n, 1)))
    stay = np.where(weekend, rng.uniform(2.0, 6.0, (n_days, n, 1)),
                    rng.normal(17.5, 1.0, (n_days, n, 1)) - arrive)
    leave = arrive + np.clip(stay, 1.0, 13.0)
    lunch_out = (rng.random((n_days, n, 1)) < 0.5) & ~weekend
    inside = present & (h >= arrive) & (h < leave) & ~(lunch_out & (h >= 12.0) & (h < 13.0))
    if weekend_work > 0:  # drawn after the rest, so weekend_work = 0 leaves the stream as it was
        works = weekend & (rng.random((n_days, n, 1)) < 0.85 * weekend_work)
        w_arrive = rng.normal(9.5, 1.0, (n_days, n, 1))
        w_leave = w_arrive + np.clip(rng.normal(16.5, 1.0, (n_days, n, 1)) - w_arrive, 1.0, 12.0)
        inside |= works & (h >= w_arrive) & (h < w_leave)
    return inside.mean(axis=1)


def occupancy_profiles(cfg: BuildingConfig, days: pd.DatetimeIndex, seed: int) -> dict[str, np.ndarray]:
    """Per room (n_days, 96) fractions of people, lights and equipment.

    Returns a dict with keys ``occ:<room>``, ``lights:<room>``, ``equip:<room>``.
    """
    rng = rng_for(seed, "occupancy")
    out: dict[str, np.ndarray] = {}
    office = {}
    for name, room in cfg.rooms.items():
        kind = cfg.kinds[room.kind]
        if kind.occupancy == "office":
            n = round(kind.people_per_m2 * room.floor_area)
            office[name] = office_occupancy(days, n, rng, cfg.weekend_occupancy)
    mean_office = np.mean(list(office.values()), axis=0) if office else np.zeros((len(days), 96))
    n_days = len(days)
    for name, room in cfg.rooms.items():
        kind = cfg.kinds[room.kind]
        if kind.occupancy == "office":
            occ = office[name]
        elif kind.occupancy == "transit":
            occ = np.clip(mean_office * rng.uniform(0.3, 0.7) + rng.normal(0, 0.03, mean_office.shape), 0, 1)
        else:
            occ = np.zeros((n_days, 96))
        # lights: on when someone is in, a night/security base, evening cleaning on some days
        h = _hours(n_days)[None, :]
        clean = (rng.random((n_days, 1)) < 0.6) & (h >= 19.0) & (h < 20.5)
        lights = np.clip(0.08 + 0.92 * np.minimum(1.0, 2.5 * occ) + 0.5 * clean, 0, 1)
        if kind.occupancy == "none":
            lights = np.full_like(lights, 0.15)
        # equipment: a base load plus a part that follows the people, with a daily factor
        day_factor = rng.normal(1.0, 0.12, (n_days, 1))
        equip = np.clip(kind.equipment_base + (1 - kind.equipment_base) * occ * day_factor, 0, 1)
        if kind.occupancy == "none":
            equip = np.clip(kind.equipment_base + rng.normal(0, 0.05, (n_days, 1)) + 0 * occ, 0, 1)
        out[f"occ:{name}"], out[f"lights:{name}"], out[f"equip:{name}"] = occ, lights, equip
    return out


def zone_neighbours(cfg: BuildingConfig, walls) -> dict[str, set[str]]:
    """Model zones that share at least one interior wall."""
    nb: dict[str, set[str]] = {z: set() for z in cfg.zones}
    for g in walls.values():
        for w in g.walls:
            if w.neighbour:
                a, b = cfg.rooms[w.room].zone, cfg.rooms[w.neighbour].zone
                if a != b:
                    nb[a].add(b)
                    nb[b].add(a)
    return nb


@dataclass(frozen=True)
class ExcitationBlock:
    """One 2-hour block of the paper's experiment (paper section 2-B)."""
    start: dt.datetime            # local wall clock, naive
    end: dt.datetime
    target: str                   # zone at maximum airflow
    fractions: dict               # zone -> commanded fraction of box maximum
    modes: dict                   # zone -> "max" | "min" | "random"


def excitation_plan(cfg: BuildingConfig, days: list[dt.date], neighbours: dict[str, set[str]],
                    seed: int, start_hour: int = 8, block_hours: int = 2) -> list[ExcitationBlock]:
    """Paper section 2-B: from 08:00, every 2 h one zone's boxes go to maximum airflow,
    its neighbours' to minimum and every other zone's to a random airflow; all zones in
    turn, in a random order per day (seeded)."""
    return plan_blocks(list(cfg.zones), cfg.hvac.minimum_fraction, days, neighbours, seed,
                       start_hour, block_hours)


def plan_blocks(zones: list[str], lo: float, days: list[dt.date], neighbours: dict[str, set[str]],
                seed: int, start_hour: int = 8, block_hours: int = 2) -> list[ExcitationBlock]:
    """The excitation blocks of :func:`excitation_plan` for any list of model zones.

    Parameters
    ----------
    zones : list of str
        Model zones, in a fixed order (the seeded permutation indexes it).
    lo : float
        Box minimum fraction of maximum airflow [-] for the "min" mode and the lower end of
        the "random" draws.
    days : list of date
        Excitation days; blocks start at ``start_hour`` local time [h] and last
        ``block_hours`` [h] each.
    neighbours : dict
        Model zone -> model zones sharing an interior wall with it.
    seed : int
        Seed of the excitation generator (``rng_for(seed, "excitation")``).
    """
    rng = rng_for(seed, "excitation")
    blocks = []
    for day in days:
        order = [zones[i] for i in rng.permutation(len(zones))]
        for i, target in enumerate(order):
            t0 = dt.datetime.combine(day, dt.time(start_hour)) + dt.timedelta(hours=block_hours * i)
            fr, modes = {}, {}
            for z in zones:
                if z == target:
                    fr[z], modes[z] = 1.0, "max"
                elif z in neighbours[target]:
                    fr[z], modes[z] = lo, "min"
                else:
                    fr[z], modes[z] = float(np.round(rng.uniform(lo, 1.0), 3)), "random"
            blocks.append(ExcitationBlock(t0, t0 + dt.timedelta(hours=block_hours), target, fr, modes))
    return blocks


def year_of_day(span_start: dt.date, doy_date: dt.date) -> dt.date:
    """The date in [span_start, span_start + 1 year) with the month/day of ``doy_date``."""
    d = doy_date.replace(year=span_start.year)
    return d if d >= span_start else d.replace(year=span_start.year + 1)


def schedule_table(cfg: BuildingConfig, span_start: dt.date, seed: int,
                   blocks: list[ExcitationBlock]) -> pd.DataFrame:
    """The Schedule:File table: 35040 rows (a non-leap year on the wall clock, 15-min
    items; row i covers [i*15 min, (i+1)*15 min) from 1 January) with one column per
    schedule. Day-of-year rows map to the actual date within one year from ``span_start``
    (the weekday and the random draws follow that date)."""
    ref = pd.date_range("2015-01-01", periods=365, freq="D")  # a non-leap year
    actual = pd.DatetimeIndex([year_of_day(span_start, d.date()) for d in ref])
    prof = occupancy_profiles(cfg, actual, seed)
    cols = {k: v.reshape(-1) for k, v in prof.items()}
    n = 365 * STEPS_PER_DAY
    stamps = np.repeat(actual.values, STEPS_PER_DAY) + np.tile(
        np.arange(STEPS_PER_DAY) * np.timedelta64(15, "m"), 365)
    t = pd.DatetimeIndex(stamps)
    hour = t.hour + t.minute / 60
    workday = t.day_of_week < 5
    h0, h1 = cfg.hvac.occupied_hours
    occupied = workday & (hour >= h0) & (hour < h1)
    htg = np.where(occupied, cfg.hvac.heating.occupied, cfg.hvac.heating.unoccupied)
    clg = np.where(occupied, cfg.hvac.cooling.occupied, cfg.hvac.cooling.unoccupied)
    minflow = {r: np.full(n, cfg.hvac.minimum_fraction) for r in cfg.rooms}
    pos = pd.Series(np.arange(n), index=t)
    for b in blocks:
        sel = pos[(t >= pd.Timestamp(b.start)) & (t < pd.Timestamp(b.end))].values
        if len(sel) == 0:
            raise ValueError(f"excitation block at {b.start} lies outside the simulated span")
        htg[sel], clg[sel] = cfg.hvac.experiment_heating, cfg.hvac.experiment_cooling
        for r, room in cfg.rooms.items():
            minflow[r][sel] = b.fractions[room.zone]
    cols["htg"], cols["clg"] = htg, clg
    for r in cfg.rooms:
        cols[f"minflow:{r}"] = minflow[r]
    return pd.DataFrame(cols, index=t)
