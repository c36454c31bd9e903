"""Telemetry: load, validate and convert a site's recorded points to SI on the model step.

Time convention (docs/data.md): the ``time`` of a row is the start of a step interval.
Zone temperatures in the row are the readings AT ``time`` (they are outputs y(k) of the
state x(k)); box airflows, supply and outdoor air temperatures and irradiance are the
averages over ``[time, time + step)`` (inputs u(k) and disturbances v(k) that drive the
state from x(k) to x(k+1), paper eq:model_dt). Row k therefore holds y(k), u(k), v(k).

Missing readings stay NaN (the Kalman filter handles partial measurements). Gaps in time
are allowed and reported as contiguous segments; nothing is silently dropped.
"""

from __future__ import annotations

import datetime as dt
import itertools
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from zonecast.estimator.site import Site
from zonecast.estimator.units import to_si

MISSING_TOKENS = {"", "nan", "NaN", "NA", "N/A", "null", "None"}


#: longest run of missing rows of a lights or plug-load meter that :meth:`Telemetry.power`
#: fills linearly (1 h at 15 min)
METER_FILL_STEPS = 4


def fill_short_gaps(x: np.ndarray, segments: list[tuple[int, int]], max_fill: int) -> np.ndarray:
    """``x`` with each run of at most ``max_fill`` NaNs that has a finite value on both
    sides within the same segment (``[start, stop)`` row ranges) filled by linear
    interpolation in the row index (rows are equally spaced within a segment); longer
    runs and runs at a segment's ends stay NaN."""
    out = np.array(x, float)
    for a, b in segments:
        seg = out[a:b]
        bad = ~np.isfinite(seg)
        if not bad.any() or max_fill < 1:
            continue
        edges = np.diff(np.r_[0, bad.astype(int), 0])
        for lo, hi in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True):
            if lo > 0 and hi < len(seg) and hi - lo <= max_fill:
                w = np.arange(1, hi - lo + 1) / (hi - lo + 1)
                seg[lo:hi] = seg[lo - 1] + w * (seg[hi] - seg[lo - 1])
    return out


class TelemetryError(ValueError):
    """Telemetry does not meet the contract; the message names the row, column or value."""


def _line(i: int) -> int:
    """0-based data row -> 1-based line of the CSV file (line 1 is the header)."""
    return i + 2


def _list(items, n=5) -> str:
    items = list(items)
    more = f" (and {len(items) - n} more)" if len(items) > n else ""
    return ", ".join(str(x) for x in items[:n]) + more


def parse_times(raw: pd.Series, source: str = "telemetry") -> pd.DatetimeIndex:
    """ISO-8601 strings with a UTC offset -> tz-aware UTC index; errors name the lines."""
    text = raw.astype(str).str.strip()
    parsed = pd.to_datetime(text, format="ISO8601", errors="coerce", utc=True)
    bad = np.flatnonzero(parsed.isna().to_numpy())
    if len(bad):
        raise TelemetryError(f"{source}: column 'time' has values that are not ISO-8601 times at "
                             f"lines {_list(_line(i) for i in bad)} (first: {text.iloc[bad[0]]!r})")
    no_offset = ~text.str.contains(r"(?:Z|[+-]\d\d:?\d\d)$", regex=True)
    if no_offset.any():
        rows = np.flatnonzero(no_offset.to_numpy())
        raise TelemetryError(f"{source}: times need a UTC offset (e.g. 2015-04-18T08:00:00-07:00); "
                             f"lines {_list(_line(i) for i in rows)} have none "
                             f"(first: {text.iloc[rows[0]]!r})")
    return pd.DatetimeIndex(parsed).as_unit("ns")


def check_time_axis(times: pd.DatetimeIndex, step: dt.timedelta, source: str = "telemetry") -> None:
    """Times strictly increasing, on the step grid (multiples of ``step`` since the epoch)."""
    ns = times.as_unit("ns").asi8
    d = np.diff(ns)
    dup = np.flatnonzero(d == 0)
    if len(dup):
        raise TelemetryError(f"{source}: duplicated time {times[dup[0]].isoformat()} at lines "
                             f"{_line(dup[0])} and {_line(dup[0] + 1)}; each time may appear once")
    back = np.flatnonzero(d < 0)
    if len(back):
        i = back[0]
        raise TelemetryError(f"{source}: times go backwards at line {_line(i + 1)} "
                             f"({times[i + 1].isoformat()} after {times[i].isoformat()}); sort the "
                             "file by time")
    step_ns = int(step.total_seconds() * 1e9)
    off = np.flatnonzero(ns % step_ns)
    if len(off):
        raise TelemetryError(f"{source}: time {times[off[0]].isoformat()} at line {_line(off[0])} is "
                             f"not on the {step} grid; resample to the site's step "
                             f"({len(off)} rows are off the grid)")


def segments_of(times: pd.DatetimeIndex, step: dt.timedelta) -> list[tuple[int, int]]:
    """Contiguous runs of rows ``[start, stop)`` with no missing step between them."""
    if len(times) == 0:
        return []
    gaps = np.flatnonzero(np.diff(times.as_unit("ns").asi8) != int(step.total_seconds() * 1e9)) + 1
    bounds = [0, *gaps.tolist(), len(times)]
    return list(itertools.pairwise(bounds))


@dataclass
class Telemetry:
    """Validated telemetry in SI units on the site's step.

    Attributes
    ----------
    frame : DataFrame indexed by UTC time, one column per site point, SI units
        (degC, kg/s, W/m2); missing readings are NaN.
    site : the site description.
    segments : contiguous row ranges ``[start, stop)``.
    unused_columns : columns of the file that the site does not map (kept, not used).
    """

    frame: pd.DataFrame
    site: Site
    segments: list[tuple[int, int]]
    unused_columns: list[str] = field(default_factory=list)

    @property
    def times(self) -> pd.DatetimeIndex:
        return self.frame.index

    def local_times(self) -> pd.DatetimeIndex:
        return self.frame.index.tz_convert(self.site.tz)

    def airflow(self) -> np.ndarray:
        """u(k): box airflows (N, n_boxes) [kg/s], boxes in site order."""
        return self.frame[[b.airflow.point for b in self.site.boxes.values()]].to_numpy()

    def discharge_rise(self) -> np.ndarray:
        """Discharge-air temperature of each box above the supply air (N, n_boxes) [K], boxes
        in site order: T_discharge - T_supply, the rise a reheat coil (or duct) adds. Zero for
        a box without a discharge-air point; NaN where the point or the supply air did not
        report."""
        ts = self.frame[self.site.points.supply_air_temperature.point].to_numpy()
        out = np.zeros((len(self.frame), len(self.site.boxes)))
        for j, b in enumerate(self.site.boxes.values()):
            if b.discharge_temperature is not None:
                out[:, j] = self.frame[b.discharge_temperature.point].to_numpy() - ts
        return out

    def power(self, max_fill: int = METER_FILL_STEPS) -> np.ndarray | None:
        """Metered electric power of each model zone's lights and plug loads (N, n_zones)
        [W], zones in site order: the sum of the zone's meters (``points.power``). A
        meter's run of at most ``max_fill`` missing rows between two readings of the same
        segment is filled linearly (a zone's sum is not lost to one meter's dropped
        message); NaN where a meter's gap is longer, at a segment's ends, or where the zone
        has none. None when the site maps no meter."""
        meters = self.site.points.power
        if not meters:
            return None
        out = np.full((len(self.frame), len(self.site.zones)), np.nan)
        for j, zone in enumerate(self.site.zones):
            if zone in meters:
                cols = [fill_short_gaps(self.frame[m.point].to_numpy(float), self.segments,
                                        max_fill) for m in meters[zone]]
                out[:, j] = np.sum(cols, axis=0)
        return out

    def weather(self) -> pd.DataFrame:
        """Outdoor air [degC], supply air [degC], GHI, DNI, DHI [W/m2] and the cloud cover
        ``cloud`` [-] (NaN throughout for a site without a ``cloud_cover`` point)."""
        p = self.site.points
        cols = {"Ta": p.outdoor_air_temperature.point, "Ts": p.supply_air_temperature.point,
                "ghi": p.solar.global_horizontal.point, "dni": p.solar.direct_normal.point,
                "dhi": p.solar.diffuse_horizontal.point}
        out = pd.DataFrame({k: self.frame[v].to_numpy() for k, v in cols.items()},
                           index=self.frame.index)
        cloud = p.cloud_cover
        out["cloud"] = np.nan if cloud is None else self.frame[cloud.point].to_numpy()
        return out

    def zone_sensors(self, zone: str) -> np.ndarray:
        """Readings (N, n_sensors) [degC] of a model zone's temperature sensors."""
        return self.frame[[s.point for s in self.site.points.zone_temperature[zone]]].to_numpy()

    def zone_temperature(self, weights: dict[str, np.ndarray] | None = None) -> np.ndarray:
        """ȳ(k): measured zone temperatures (N, n_zones) [degC].

        A zone with several sensors is their weighted mean (equal weights unless
        ``weights[zone]`` is given, e.g. room air volumes) over the sensors that
        reported; NaN where none did.
        """
        out = np.full((len(self.frame), len(self.site.zones)), np.nan)
        for j, zone in enumerate(self.site.zones):
            vals = self.zone_sensors(zone)
            w = np.ones(vals.shape[1]) if weights is None or zone not in weights \
                else np.asarray(weights[zone], float)
            ok = np.isfinite(vals)
            wsum = (ok * w).sum(axis=1)
            with np.errstate(invalid="ignore", divide="ignore"):
                out[:, j] = np.where(wsum > 0, np.nansum(vals * w, axis=1) / wsum, np.nan)
        return out

    def slice(self, start, end) -> Telemetry:
        """Rows with start <= time < end (tz-aware bounds)."""
        sub = self.frame[(self.frame.index >= start) & (self.frame.index < end)]
        return Telemetry(sub, self.site, segments_of(sub.index, self.site.step),
                         self.unused_columns)


def _numeric(df: pd.DataFrame, col: str, source: str) -> np.ndarray:
    s = df[col]
    if s.dtype.kind in "fi":
        return s.to_numpy(dtype=float)
    text = s.astype(str).str.strip()
    missing = text.isin(MISSING_TOKENS) | s.isna()
    vals = pd.to_numeric(text.where(~missing), errors="coerce")
    bad = np.flatnonzero((vals.isna() & ~missing).to_numpy())
    if len(bad):
        raise TelemetryError(f"{source}: column {col!r} has non-numeric values at lines "
                             f"{_list(_line(i) for i in bad)} (first: {text.iloc[bad[0]]!r}); "
                             "leave a cell empty for a missing reading")
    return vals.to_numpy(dtype=float)


def load_telemetry(path: str | Path, site: Site) -> Telemetry:
    """Read a telemetry file (CSV, or Parquet with pyarrow installed) and validate it
    against ``site``: a ``time`` column (ISO-8601 with offset, strictly increasing, on the
    step grid) and every point the site maps, numeric, converted to SI units."""
    path = Path(path)
    source = str(path.name)
    if not path.is_file():
        raise TelemetryError(f"telemetry file {path} not found")
    if path.suffix == ".parquet":
        try:
            df = pd.read_parquet(path)
        except ImportError:
            raise TelemetryError("reading Parquet needs pyarrow: pip install pyarrow, or use CSV")
    else:
        df = pd.read_csv(path, dtype=str, keep_default_na=False)
    if "time" not in df.columns:
        raise TelemetryError(f"{source}: no 'time' column; the first column must be 'time' "
                             f"(found {_list(df.columns)})")
    units = site.point_units()
    missing = [p for p in units if p not in df.columns]
    if missing:
        raise TelemetryError(f"{source}: missing columns for points the site maps: "
                             f"{_list(missing, 10)}")
    times = parse_times(df["time"], source)
    check_time_axis(times, site.step, source)
    data = {p: to_si(_numeric(df, p, source), u) for p, u in units.items()}
    frame = pd.DataFrame(data, index=times)
    frame.index.name = "time"
    unused = [c for c in df.columns if c != "time" and c not in units]
    return Telemetry(frame, site, segments_of(times, site.step), unused)
