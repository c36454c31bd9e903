"""A short report of a virtual-building run: floor plan, excitation, gains, weather."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle
from zonecast.estimator.site import load_site
from zonecast.estimator.telemetry import load_telemetry
from zonecast.testbed.config import load_config
from zonecast.testbed.geometry import plan_walls

ZONE_COLOURS = {"NW": "#4e79a7", "W": "#f28e2b", "S": "#e15759", "E": "#76b7b2",
                "NE": "#59a14f", "C": "#edc948"}


def _gain_parts(truth: pd.DataFrame) -> tuple[str, ...]:
    """The truth's gain columns that warm the air: people's sensible heat (campaigns written
    before 2026-12-06 have their total only), lights, equipment. The testbed writes this
    contract and may not import the estimator's reader of it (tests/test_architecture.py)."""
    people = ("people_sensible" if any(c.startswith("people_sensible:") for c in truth.columns)
              else "people")
    return (people, "lights", "equipment")


def plot_floor(cfg, path: Path) -> None:
    fig = Figure(figsize=(9, 4.8))
    ax = fig.subplots()
    walls = plan_walls({n: r.rect for n, r in cfg.rooms.items()})
    for name, room in cfg.rooms.items():
        x0, y0, x1, y1 = room.rect
        ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fc=ZONE_COLOURS.get(room.zone, "#ccc"),
                                   ec="k", alpha=0.55))
        ax.text((x0 + x1) / 2, (y0 + y1) / 2, f"{name}\n{room.kind}", ha="center", va="center",
                fontsize=7)
        if room.windows:
            for w in walls[name].walls:
                if w.neighbour is None:
                    ax.plot([w.a[0], w.b[0]], [w.a[1], w.b[1]], color="#1f77b4", lw=4)
    ax.set_aspect("equal")
    ax.autoscale()
    ax.set_xlabel("x [m] (east)")
    ax.set_ylabel("y [m] (north)")
    ax.set_title(f"{cfg.name}: model zones (colour), windows (blue), one VAV box per room")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def plot_excitation(tel, site, day: pd.Timestamp, path: Path) -> None:
    local = tel.local_times()
    sel = (local >= day - pd.Timedelta(hours=12)) & (local < day + pd.Timedelta(days=2))
    y = tel.zone_temperature()[sel]
    u = tel.airflow()[sel]
    fig = Figure(figsize=(10, 6))
    (a1, a2) = fig.subplots(2, 1, sharex=True)
    boxes = list(site.boxes.values())
    for j, z in enumerate(site.zones):
        c = ZONE_COLOURS.get(z)
        a1.plot(local[sel], y[:, j], color=c, label=z)
        cols = [i for i, b in enumerate(boxes) if b.room in site.zones[z]]
        a2.plot(local[sel], u[:, cols].sum(axis=1), color=c, label=z)
    a1.set_ylabel("zone temperature [°C]")
    a2.set_ylabel("zone airflow [kg/s]")
    a1.legend(ncol=6, fontsize=8)
    a1.set_title("Excitation weekend (paper §2-B): one zone at maximum airflow every 2 h")
    fig.autofmt_xdate()
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def plot_gains(truth: pd.DataFrame, zones, tz, path: Path) -> None:
    """True internal heat per zone on a time-of-week axis: weeks in grey, mean in red."""
    local = pd.DatetimeIndex(truth.index).tz_convert(tz)
    tow = (local.day_of_week * 96 + local.hour * 4 + local.minute // 15).to_numpy()
    week = (local - pd.to_timedelta(tow * 15, unit="m")).normalize()
    fig = Figure(figsize=(10, 1.6 * len(zones)))
    axes = fig.subplots(len(zones), 1, sharex=True)
    for ax, z in zip(np.atleast_1d(axes), zones):
        q = sum(truth[f"{k}:zone:{z}"] for k in _gain_parts(truth)).to_numpy() / 1e3
        frame = pd.DataFrame({"tow": tow, "week": week, "q": q})
        table = frame.pivot_table(index="tow", columns="week", values="q")
        ax.plot(table.index / 96, table.values, color="0.7", lw=0.6)
        ax.plot(table.index / 96, table.mean(axis=1), color="red", lw=1.2)
        ax.set_ylabel(f"{z} [kW]")
    np.atleast_1d(axes)[-1].set_xlabel("day of week (0 = Monday), local time")
    fig.suptitle("True internal gains (people's sensible heat + lights + equipment): "
                 "each week grey, mean red")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def plot_weather(tel, path: Path) -> None:
    w = tel.weather()
    local = tel.local_times()
    fig = Figure(figsize=(10, 5))
    (a1, a2) = fig.subplots(2, 1, sharex=True)
    a1.plot(local, w.Ta, ".", ms=1, label="outdoor air")
    a1.plot(local, w.Ts, ".", ms=1, label="AHU supply air")
    a1.set_ylabel("[°C]")
    a1.legend(markerscale=8)
    a2.plot(local, w.ghi, ".", ms=1)
    a2.set_ylabel("GHI [W/m²]")
    fig.suptitle("Weather and supply air over the campaign weeks")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def write_report(run_dir: Path, out: Path) -> Path:
    """Write ``out/report.md`` and figures for a virtual-building run folder."""
    run_dir, out = Path(run_dir), Path(out)
    out.mkdir(parents=True, exist_ok=True)
    meta = json.loads((run_dir / "run.json").read_text())
    cfg = load_config(meta["building"])
    site = load_site(run_dir / "site.yaml")
    tel = load_telemetry(run_dir / "telemetry.csv", site)
    truth = pd.read_csv(run_dir / "truth.csv", index_col=0)
    truth.index = pd.to_datetime(truth.index, utc=True)
    plot_floor(cfg, out / "floor_plan.png")
    figs = ["floor_plan.png"]
    if meta["excitation_weekends"]:
        day = pd.Timestamp(meta["excitation_weekends"][0], tz=site.timezone)
        plot_excitation(tel, site, day, out / "excitation.png")
        figs.append("excitation.png")
    plot_gains(truth, list(site.zones), site.timezone, out / "internal_gains_truth.png")
    plot_weather(tel, out / "weather.png")
    figs += ["internal_gains_truth.png", "weather.png"]
    y = tel.zone_temperature()
    rows = []
    for j, z in enumerate(site.zones):
        rooms = site.zones[z]
        area = sum(cfg.rooms[r].floor_area for r in rooms)
        gains = sum(truth[f"{k}:zone:{z}"] for k in _gain_parts(truth)).mean()
        rows.append(f"| {z} | {len(rooms)} | {area:.0f} | {np.nanmean(y[:, j]):.2f} | "
                    f"{np.nanstd(y[:, j]):.2f} | {gains / area:.1f} | "
                    f"{truth[f'reheat:zone:{z}'].mean() / area:.1f} |")
    lines = [f"# Virtual building {meta['building']}: campaign report", "",
             (f"Seed {meta['seed']}; EnergyPlus {meta['energyplus']}; weeks "
              f"{', '.join(meta['weeks'])}; excitation weekends "
              f"{', '.join(meta['excitation_weekends'])}."),
             (f"Simulation: EnergyPlus {meta['timings']['energyplus_s']:.1f} s, whole run "
              f"{meta['timings']['total_s']:.1f} s. {len(tel.frame)} steps of 15 min in "
              f"{len(tel.segments)} segments."), "",
             "| zone | rooms | floor area [m²] | mean T [°C] | std T [°C] | mean gains [W/m²] | mean reheat [W/m²] |",
             "|---|---|---|---|---|---|---|", *rows, ""]
    lines += [f"![{f}]({f})" for f in figs]
    path = out / "report.md"
    path.write_text("\n".join(lines) + "\n")
    return path
