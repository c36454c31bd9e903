"""The served forecast with and without the thermostat's reheat, its cooling, or the young
filter after restarts (issue 15).

For each member: the served forecasts (``Pipeline.forecast`` of the member's ``zonecast
reproduce`` model, the testbed's weather forecasts as designed, seed 0) at the 18
validation midnights, once with the boxes' learned discharge-air rise
(``streaming.REHEAT_CONTROL`` off) and once with the rooms' thermostats' reheat (on);
prints the RMS per zone, the ratio to the known-input forecast of the member's report and
the calibrated 90 % coverage. docs/forecasts.md "Reheat as the thermostat's answer".

    python benchmarks/bench_reheat_control.py --reports DIR --family DIR [--extra CAMPAIGN ...]
                                              [--only NAME ...] [--side reheat|cooling|young]

``--side cooling``: both runs with the reheat controller, the second also with the
cooling controller (``streaming.COOLING_CONTROL``; docs/forecasts.md "Cooling as the
thermostat's answer"). ``--side young``: both runs with both controllers, the first with
the steady-state filter from every start, the second with the young filter's gains after
each start (``streaming.YOUNG_FILTER``; docs/forecasts.md "The filter after a restart").
``--side young-std``: both runs with both controllers and the young filter, the first
with the steady filter's forecast std for every forecast, the second with the young
filter's while it runs (``streaming.YOUNG_STD``). ``--side day-class``: both runs with
the library's defaults, the first with the intervals calibrated on all days pooled, the
second per day class of the target (``streaming.DAY_CLASS_INTERVALS``; docs/forecasts.md
"Intervals by day class"). ``--side weather-spread``: both runs with the library's
defaults, the first with the intervals scaling the model's std alone, the second the std
widened by the forecast's sensitivity to the weather forecast's learned error
(``streaming.WEATHER_SPREAD``; docs/forecasts.md "Intervals that know the weather's
error"). ``--side gains-level``: both runs with the library's defaults, the second with
the served gains' slow level (``streaming.GAINS_LEVEL_TAU`` = ``--level-tau``, default
24 h; docs/forecasts.md "The gains' slow level"). ``--side spread-sides``: both runs with the
library's defaults, the second with the weather perturbed both ways
(``streaming.WEATHER_SPREAD_TWO_SIDED``; docs/forecasts.md "The weather's spread both
ways"). ``--side closed-loop``: both runs with the library's defaults, the second with
the model's std scaled by the share of a heat input the rooms' thermostats let through
(``streaming.CLOSED_LOOP_STD``; docs/forecasts.md "How precise a member's coverage is").
``--side monday-fill``: both runs with the library's defaults, the first with the
profile's empty day (Monday, each week's warm-up) filled from every other day, the second
from the days of its operating day's class (``forecast.PROFILE_FILL``, ``--fill OFF ON``,
default ``all operating``; docs/forecasts.md "Monday's gains"). ``--side deadband``: both
runs with the library's defaults, the second with the boxes inside the dead band throttled
to their learned minimum airflow (``streaming.DEADBAND_CONTROL``; docs/forecasts.md "The
dead band's airflow"). ``--side learn-empty``: both runs with the library's defaults, the
second with the profile's empty bins (Monday) learned from the building's own per-step
gains as it operates (``streaming.PROFILE_LEARN_EMPTY``; docs/forecasts.md "Monday's gains
from Mondays"). ``--side after-off``: both runs with the library's defaults, the second
with the intervals calibrated on a day class of their own for the working days after a
day off (``streaming.AFTER_OFF_INTERVALS``; docs/forecasts.md "The day after a day off";
since the thirty-third session a shadow calibrator in the first run's replay, as below:
checked against a run with the option on office6's campaign, the same coverage).
``--side aci-feedback``: both with the library's defaults, the first with the adaptive
level's misses judged against the quantiles when the measurement arrives, the second
against the interval each forecast was served with (``streaming.ACI_FEEDBACK``;
docs/forecasts.md "The adaptive level's feedback"); one replay gives both (a shadow
calibrator beside the estimator's: the calibration changes no forecast, only its interval).
``--side interval-scale``: the same, the second with the level fixed and a factor on the
half-width moved by the served intervals' misses (``streaming.INTERVAL_ADAPT``).
``--side settled-calibration``: the library's defaults, the second without calibration
forecasts from the filter's first ``YOUNG_STEPS`` steps after each start
(``streaming.CALIBRATE_YOUNG``; docs/forecasts.md "The calibration after a restart"; a
shadow calibrator as well). ``--side weather-blend``: the library's defaults, the first
with the weather forecast served as received, the second combined with the diurnal
fallback by weights learned per lead (``streaming.WEATHER_BLEND``; docs/forecasts.md
"Forecast and the recent days, combined").
``--side defaults``: one run with the library's defaults. ``--dump DIR`` writes
each run's forecasts, intervals, measurements and target times (``.npz``) for analyses
after the run (``benchmarks/coverage_analysis.py``). ``--stream FAMILY`` replays the
members' telemetry from a family run with ``--continuous`` (every week from the first to
the last, no gaps), with the campaign's model and profile, scored at the campaign's
validation midnights (docs/forecasts.md "How precise a member's coverage is");
``--all-midnights`` scores every local midnight of the stream instead (from its eighth
day on, no experiment in the 24 h; the training weeks' too, whose gains the profile saw),
``--issue-weekdays 0`` only those that start a Monday, ``--issue-hours 0 6 12 18`` at those
local hours of every day instead of midnight alone. ``--known`` also replays each run with
the measured inputs (the served / known ratio of the same estimator). The served
forecasts' weekly gains profile is re-estimated from the forecast study's training weeks
(``--profile train``, the default since 2026-12-05) as in ``zonecast reproduce``'s model
file; ``--profile file`` takes the model file's (``zonecast identify`` writes the profile of
every whole week, the validation weeks included: the tables of the day classes and the
weather's spread were measured so). Every other side runs with the library's defaults for the young filter, the
day classes and the weather spread. The last column is the coverage of the targets on the
site's working days, on its other days (weekends, holidays) and on the working days after
a day off (Mondays, the day after a holiday).

``--reports`` is a ``bench_family.py --out`` folder (``<name>/model.json``,
``<name>/results.json``); campaigns are ``--family/<name>`` or the ``--extra`` folders.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices: threads only contend

import argparse
import json
import platform
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
from zonecast.estimator import forecast as forecast_module
from zonecast.estimator import streaming
from zonecast.estimator.calibration import IntervalCalibrator
from zonecast.estimator.constants import HORIZON, STEP
from zonecast.estimator.evaluate import rms_by_zone
from zonecast.estimator.forecast import week_split
from zonecast.estimator.inputs_forecast import DayCalendar
from zonecast.estimator.pipeline import Pipeline
from zonecast.estimator.site import load_site
from zonecast.estimator.telemetry import load_telemetry
from zonecast.estimator.weather_forecast import parse_weather_forecast
from zonecast.testbed.forecasts import weather_forecasts

from zonecast.jobs.reproduce import (
    _interval_coverage,
    has_discharge,
    measured_inputs,
    validation_issues,
)


def served(campaign: Path, model: Path, control: bool,
           side: str = "reheat") -> tuple[dict, dict, float, tuple[float, float]]:
    """RMS per zone, coverage and seconds of the served forecasts with the controller
    ``control`` on or off: the reheat (``side`` "reheat"), with the reheat on the cooling
    ("cooling"), or with both on the young filter ("young"); and the coverage of the
    targets on working days and on other days."""
    site = load_site(campaign / "site.yaml")
    data = Pipeline.from_site(campaign / "site.yaml").data(campaign / "telemetry.csv")
    issues = validation_issues(data, 0)
    # the telemetry replayed: the campaign's, or (``--stream``) the same building operated
    # without the campaign's gaps, scored at the same validation midnights and leads
    src = campaign if STREAM is None else STREAM / campaign.name
    frame = load_telemetry(src / "telemetry.csv", site).frame
    weather = [parse_weather_forecast(b) for b in weather_forecasts(site, frame, seed=0)]
    sdata = data  # the data the scored issues' rows index
    if STREAM is not None:
        sdata = Pipeline.from_site(src / "site.yaml").data(src / "telemetry.csv")
        row_of = {t: i for i, t in enumerate(sdata.times)}
        missing = [data.times[r] for r, _ in issues if data.times[r] not in row_of]
        if missing:
            raise SystemExit(f"{src}: no row at the validation midnight {missing[0]}")
        # the campaign's validation midnights and leads, as rows of the stream
        issues = ([(row_of[data.times[r]], row_of[data.times[r]] + stop - r)
                   for r, stop in issues] if not ALL_MIDNIGHTS
                  else stream_midnights(sdata, site, ISSUE_WEEKDAYS, ISSUE_HOURS))
    nz = len(data.zones)
    before = (streaming.REHEAT_CONTROL, streaming.COOLING_CONTROL, streaming.YOUNG_FILTER,
              streaming.YOUNG_STD, streaming.DAY_CLASS_INTERVALS, streaming.WEATHER_SPREAD,
              streaming.GAINS_LEVEL_TAU, streaming.WEATHER_SPREAD_TWO_SIDED,
              streaming.CLOSED_LOOP_STD, forecast_module.PROFILE_FILL,
              streaming.DEADBAND_CONTROL, streaming.PROFILE_LEARN_EMPTY,
              streaming.AFTER_OFF_INTERVALS, streaming.ACI_FEEDBACK,
              streaming.INTERVAL_ADAPT, streaming.CALIBRATE_YOUNG, streaming.WEATHER_BLEND)
    # read by each OnlineEstimator the pipeline makes
    if side == "reheat":
        streaming.REHEAT_CONTROL = control
    elif side == "cooling":
        streaming.REHEAT_CONTROL, streaming.COOLING_CONTROL = True, control
    elif side == "young":
        streaming.REHEAT_CONTROL = streaming.COOLING_CONTROL = True
        streaming.YOUNG_FILTER = control
    elif side == "young-std":
        streaming.REHEAT_CONTROL = streaming.COOLING_CONTROL = streaming.YOUNG_FILTER = True
        streaming.YOUNG_STD = control
    elif side == "day-class":  # the library's defaults but for the intervals' day classes
        streaming.DAY_CLASS_INTERVALS = control
    elif side == "weather-spread":  # the library's defaults but for the weather's spread
        streaming.WEATHER_SPREAD = control
    elif side == "gains-level":  # the library's defaults but for the gains' slow level
        streaming.GAINS_LEVEL_TAU = LEVEL_TAU if control else None
    elif side == "spread-sides":  # the library's defaults but the weather's spread both ways
        streaming.WEATHER_SPREAD_TWO_SIDED = control
    elif side == "closed-loop":  # the library's defaults but the std of the held rooms
        streaming.CLOSED_LOOP_STD = control
    elif side == "monday-fill":  # the library's defaults but how the profile's empty day
        forecast_module.PROFILE_FILL = FILLS[control]  # is filled (read by train_profile)
    elif side == "deadband":  # the library's defaults but the dead band's airflow
        streaming.DEADBAND_CONTROL = control
    elif side == "learn-empty":  # the library's defaults but the profile's empty bins
        streaming.PROFILE_LEARN_EMPTY = control  # learned online
    elif side == "after-off":  # the library's defaults but a day class of the intervals
        streaming.AFTER_OFF_INTERVALS = control  # for the working day after a day off
    elif side == "aci-feedback":  # the adapted level (before 2026-12-05), judged by the
        streaming.INTERVAL_ADAPT = "level"  # current interval, or by the served one
        streaming.ACI_FEEDBACK = "served" if control else "current"
    elif side == "interval-scale":  # the adapted level judged by the current interval
        streaming.ACI_FEEDBACK = "current"  # (before 2026-12-05), or the tracked factor
        streaming.INTERVAL_ADAPT = "scale" if control else "level"
    elif side == "settled-calibration":  # the library's defaults but the calibration
        streaming.CALIBRATE_YOUNG = not control  # without the young filter's forecasts
    elif side == "weather-blend":  # the library's defaults but the weather forecast
        streaming.WEATHER_BLEND = control  # combined with the fallback by learned weights
    # "defaults": the library's defaults (one run, ``control`` ignored)
    # the second setting's calibrator beside the first's, in the same replay
    shadow = side in SHADOW_SIDES and not control
    if side in SHADOW_SIDES and control and campaign.name in _SHADOW_RUNS:
        return _SHADOW_RUNS.pop(campaign.name)
    shadow_hw: dict[int, np.ndarray] = {}
    patched = _shadow_calibrator(shadow_hw, SHADOW_SIDES[side]) if shadow else None
    try:
        t0 = time.perf_counter()
        pipe = Pipeline.from_model_file(model)
        if PROFILE == "train":  # the validation weeks' own gains out of the profile
            pipe = train_profile(pipe, data, model)
        times = [sdata.times[r] for r, _ in issues]
        fcs = pipe.forecast(src / "telemetry.csv", times, weather=weather)
        seconds = time.perf_counter() - t0
        if KNOWN:  # the same estimator's forecasts with the measured inputs (reproduce's)
            rh = has_discharge(pipe.bundle)
            measured = {sdata.times[r]: measured_inputs(sdata, r, r + HORIZON, rh)
                        for r, _ in issues}
            measured = {t: a for t, a in measured.items()
                        if len(a) == HORIZON and np.isfinite(a).all()}
            known_fcs = pipe.forecast_variants(src / "telemetry.csv", times,
                                               {"known": measured})["known"]
    finally:
        (streaming.REHEAT_CONTROL, streaming.COOLING_CONTROL, streaming.YOUNG_FILTER,
         streaming.YOUNG_STD, streaming.DAY_CLASS_INTERVALS, streaming.WEATHER_SPREAD,
         streaming.GAINS_LEVEL_TAU, streaming.WEATHER_SPREAD_TWO_SIDED,
         streaming.CLOSED_LOOP_STD, forecast_module.PROFILE_FILL,
         streaming.DEADBAND_CONTROL, streaming.PROFILE_LEARN_EMPTY,
         streaming.AFTER_OFF_INTERVALS, streaming.ACI_FEEDBACK,
         streaming.INTERVAL_ADAPT, streaming.CALIBRATE_YOUNG, streaming.WEATHER_BLEND) = before
        if patched is not None:
            for (owner, name), fn in patched.items():
                setattr(owner, name, fn)
    pred, lo, hi, meas = (np.full((len(issues), HORIZON, nz), np.nan) for _ in range(4))
    lo2, hi2 = np.full_like(lo, np.nan), np.full_like(hi, np.nan)
    for k, (r, stop) in enumerate(issues):
        fc = fcs[sdata.times[r]]
        n = min(HORIZON, stop - r - 1)
        pred[k], lo[k], hi[k] = fc.mean, fc.lower, fc.upper
        meas[k, :n] = sdata.y[r + 1:r + 1 + n]  # a stream's own readings (its sensor noise)
        if shadow:
            hw = shadow_hw[sdata.times[r].value // STEP_NS]
            lo2[k], hi2[k] = fc.mean - hw, fc.mean + hw
    rms = rms_by_zone(pred.reshape(-1, nz), meas.reshape(-1, nz), data.zones)
    if KNOWN:
        kp = np.full_like(pred, np.nan)
        for k, (r, _) in enumerate(issues):
            if sdata.times[r] in known_fcs:
                kp[k] = known_fcs[sdata.times[r]].mean
        ok = np.isfinite(kp).all(axis=(1, 2))
        rms["known"] = rms_by_zone(kp[ok].reshape(-1, nz), meas[ok].reshape(-1, nz),
                                   data.zones)["mean"]
    if shadow:  # the served feedback's run: the same forecasts, its own intervals
        _SHADOW_RUNS[campaign.name] = _scored(campaign, site, sdata, issues, data.zones, side,
                                              True, pred, lo2, hi2, meas, dict(rms), seconds)
    return _scored(campaign, site, sdata, issues, data.zones, side, control, pred, lo, hi,
                   meas, rms, seconds)


#: sides whose two settings differ in the interval calibration alone: the second
#: setting's calibrator (these keyword arguments) runs as a shadow in the first's replay
#: (the calibration changes no forecast mean, only the intervals, so one replay gives both)
SHADOW_SIDES = {"aci-feedback": {"feedback": "served"},
                "interval-scale": {"feedback": "served", "adapt": "scale"},
                # the same calibrator, kept from forecasts of a settled filter only
                "settled-calibration": {"_settled": True},
                # a third day class: the working day after a day off (AFTER_OFF_INTERVALS)
                "after-off": {"_after_off": True}}
#: a shadow side's second results per member, made in the first setting's run
_SHADOW_RUNS: dict[str, tuple] = {}


def _shadow_calibrator(store: dict[int, np.ndarray], shadow_kw: dict) -> dict:
    """Patch :class:`IntervalCalibrator` so that each instance runs a shadow with
    ``shadow_kw`` on the same forecasts and scores, and each served half-width's shadow
    is kept in ``store`` by grid step. ``shadow_kw`` ``_settled``: the shadow keeps only
    the forecasts issued ``YOUNG_STEPS`` or more steps after the filter's start
    (``streaming.CALIBRATE_YOUNG`` False). Returns the original methods to restore, by
    (class, name)."""
    shadow_kw = dict(shadow_kw)
    settled = shadow_kw.pop("_settled", False)
    after_off = shadow_kw.pop("_after_off", False)
    orig = {n: getattr(IntervalCalibrator, n)
            for n in ("__init__", "add_forecast", "resolve", "halfwidth", "load_state_arrays")}
    learn = streaming.OnlineEstimator._learn_inputs
    init_inputs = streaming.OnlineEstimator._init_input_forecasts
    classes: dict = {}  # the estimator being made (its calendar: the shadow's classes)

    def learn_inputs(self, t, inputs, y):
        self.calibrator._age_now = self._age  # what the shadow's add_forecast asks
        return learn(self, t, inputs, y)

    def init_input_forecasts(self):
        classes["estimator"] = self  # its calendar is made before its calibrator
        return init_inputs(self)

    def init(self, *a, **kw):
        orig["__init__"](self, *a, **kw)
        sh = IntervalCalibrator.__new__(IntervalCalibrator)
        extra = {}
        if after_off:
            cal = classes["estimator"].calendar
            extra = {"day_class": cal.interval_classes, "n_classes": cal.n_interval_classes}
        orig["__init__"](sh, *a, **dict(kw, **shadow_kw, **extra))
        self._shadow = sh

    def add_forecast(self, step_index, mean, std=None):
        if not settled or self._age_now >= streaming.YOUNG_STEPS:
            orig["add_forecast"](self._shadow, step_index, mean, std)
        return orig["add_forecast"](self, step_index, mean, std)

    def resolve(self, step_index, y, std):
        orig["resolve"](self._shadow, step_index, y, std)
        return orig["resolve"](self, step_index, y, std)

    def halfwidth(self, step_index, std):
        store[int(step_index)] = orig["halfwidth"](self._shadow, step_index, std)
        return orig["halfwidth"](self, step_index, std)

    def load_state_arrays(self, arrays, prefix="cal_"):
        raise RuntimeError("the aci-feedback shadow does not restore checkpoints")

    for name, fn in (("__init__", init), ("add_forecast", add_forecast), ("resolve", resolve),
                     ("halfwidth", halfwidth), ("load_state_arrays", load_state_arrays)):
        setattr(IntervalCalibrator, name, fn)
    streaming.OnlineEstimator._learn_inputs = learn_inputs
    streaming.OnlineEstimator._init_input_forecasts = init_input_forecasts
    return ({(IntervalCalibrator, n): fn for n, fn in orig.items()}
            | {(streaming.OnlineEstimator, "_learn_inputs"): learn,
               (streaming.OnlineEstimator, "_init_input_forecasts"): init_inputs})


def _scored(campaign, site, sdata, issues, zones, side, control, pred, lo, hi, meas, rms,
            seconds):
    """served()'s results of one run's forecasts and intervals (and its ``--dump``)."""
    # coverage by the targets' day class (the site's calendar)
    cal = DayCalendar.for_site(site)
    targets = np.array([[sdata.times[r].value + (h + 1) * STEP_NS for h in range(HORIZON)]
                        for r, _ in issues])
    klass = cal.interval_classes(targets.reshape(-1)).reshape(targets.shape)
    other = klass == 1
    inside = (meas >= lo) & (meas <= hi)
    seen = np.isfinite(meas)
    by_class = tuple(float((inside & seen & m[:, :, None]).sum() / max((seen & m[:, :, None]).sum(), 1))
                     for m in (~other, other, klass == 2))
    if DUMP is not None:  # every served forecast of the run, for analyses after it
        DUMP.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(DUMP / f"{campaign.name}-{side}-{'on' if control else 'off'}.npz",
                            pred=pred, lower=lo, upper=hi, meas=meas, targets=targets,
                            other_days=other, zones=np.array(zones),
                            issue_weekday=np.array([sdata.times[r].tz_convert(site.timezone)
                                                    .day_of_week for r, _ in issues]),
                            issue_hour=np.array([sdata.times[r].tz_convert(site.timezone).hour
                                                 for r, _ in issues]))
    return rms, _interval_coverage(lo, hi, meas, zones), seconds, by_class


STEP_NS = STEP.value
#: the slow level's time constant tried by ``--side gains-level`` (``--level-tau``)
LEVEL_TAU = pd.Timedelta("24h")
#: also the forecasts with the measured inputs (``--known``): the served / known ratio in-run
KNOWN = False
#: a family folder of the same members operated without the campaign's gaps
#: (``zonecast testbed family --continuous``; ``--stream``), or None
STREAM: Path | None = None
#: with STREAM: score every local midnight of the stream (``--all-midnights``), not only
#: the campaign's validation midnights
ALL_MIDNIGHTS = False
#: ``--side monday-fill``: the profile's fill off and on (``--fill``;
#: ``forecast.PROFILE_FILL``)
FILLS = ("all", "operating")
#: with ALL_MIDNIGHTS: the local weekdays of the issues scored (``--issue-weekdays``), or None
ISSUE_WEEKDAYS: list[int] | None = None
#: with ALL_MIDNIGHTS: the local hours of the issues scored (``--issue-hours``; midnight alone
#: by default)
ISSUE_HOURS: tuple[int, ...] = (0,)
#: folder for each run's forecasts, intervals and measurements (``--dump``), or None
DUMP: Path | None = None
#: the served forecast's weekly gains profile: "train" (the training weeks', ``--profile``)
#: or "file" (the model file's)
PROFILE = "train"


def stream_midnights(sdata, site, weekdays=None, hours=(0,)) -> list[tuple[int, int]]:
    """(issue row, issue row + HORIZON + 1) at every local midnight of a stream from its
    eighth day on (a week for the learners) whose next 24 h are all present and touch no
    experiment (``--all-midnights``); with ``weekdays`` only the midnights that start those
    local weekdays (0 = Monday; ``--issue-weekdays``); with ``hours`` every local hour of
    those (``--issue-hours``; the weekday is the issue's)."""
    times = sdata.times
    local = times.tz_convert(site.timezone)
    exps = [(pd.Timestamp(e.start), pd.Timestamp(e.end)) for e in site.experiments]
    day = pd.Timedelta("24h")
    out = []
    for r in np.flatnonzero(np.isin(local.hour, list(hours)) & (local.minute == 0)):
        t = times[r]
        if r < 7 * 96 or r + HORIZON >= len(times) or times[r + HORIZON] - t != day:
            continue
        if any(a < t + day and b > t for a, b in exps):
            continue
        if weekdays is not None and local[r].day_of_week not in weekdays:
            continue
        out.append((int(r), int(r) + HORIZON + 1))
    return out


def train_profile(pipe: Pipeline, data, model: Path) -> Pipeline:
    """``pipe`` with its weekly gains profile re-estimated from the forecast study's training
    weeks only (as ``zonecast reproduce``'s model file; ``zonecast identify`` writes the
    profile of every whole week, the validation weeks included)."""
    pipe.weekly_profile(data, weeks=week_split(data, 0)["train"])
    with tempfile.TemporaryDirectory() as tmp:
        path = pipe.write_model_file(Path(tmp) / model.name,
                                     extra={"profile_weeks": pipe.profile_weeks})
        return Pipeline.from_model_file(path)


def _find(doc, key):
    if isinstance(doc, dict):
        if key in doc:
            return doc[key]
        for v in doc.values():
            hit = _find(v, key)
            if hit is not None:
                return hit
    return None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--reports", type=Path, required=True)
    ap.add_argument("--family", type=Path)
    ap.add_argument("--extra", type=Path, nargs="*", default=[])
    ap.add_argument("--only", nargs="*")
    ap.add_argument("--side", choices=("reheat", "cooling", "young", "young-std", "day-class",
                                       "weather-spread", "gains-level", "spread-sides",
                                       "closed-loop", "monday-fill", "deadband", "learn-empty",
                                       "after-off", "aci-feedback", "interval-scale",
                                       "settled-calibration", "weather-blend", "defaults"),
                    default="reheat",
                    help="what is compared off and on: the reheat controller (the cooling "
                         "off), the cooling controller (the reheat on in both), or the young "
                         "filter after restarts (both controllers on), its forecast "
                         "std (the young filter on), the intervals' day classes, or the "
                         "weather's spread in the intervals, or the served gains' slow level "
                         "(off: the profile and the short offset), or the weather's spread both "
                         "ways, or the model's std scaled by the thermostats' hold, or the "
                         "profile's empty day (Monday) filled from every day or its own class; "
                         "'defaults': one run with the library's defaults")
    ap.add_argument("--stream", type=Path,
                    help="replay each member's telemetry from STREAM/<member> (the family run "
                         "with --continuous: no gaps between the weeks), scored at the "
                         "campaign's validation midnights with the campaign's model")
    ap.add_argument("--on-only", action="store_true",
                    help="run the side's second setting only (its first is known from an "
                         "earlier run; the table repeats the second in both columns)")
    ap.add_argument("--all-midnights", action="store_true",
                    help="with --stream: score the served forecasts issued at every local "
                         "midnight of the stream from its eighth day on (no experiment in "
                         "their 24 h), not only at the campaign's validation midnights")
    ap.add_argument("--issue-weekdays", type=int, nargs="*",
                    help="with --all-midnights: score only the midnights that start these "
                         "local weekdays (0 = Monday)")
    ap.add_argument("--issue-hours", type=int, nargs="+", default=[0],
                    help="with --all-midnights: issue at these local hours of every day "
                         "(default: 0, midnight alone); the coverage by issue hour is in the "
                         "--dump files (benchmarks/coverage_analysis.py)")
    ap.add_argument("--fill", nargs=2, default=["all", "operating"],
                    choices=("all", "day", "operating"), metavar=("OFF", "ON"),
                    help="--side monday-fill: the profile's empty-day fills compared "
                         "(forecast.PROFILE_FILL; default: all operating)")
    ap.add_argument("--dump", type=Path,
                    help="write each run's forecasts, intervals, measurements and target times "
                         "to DIR/<member>-<side>-<off|on>.npz")
    ap.add_argument("--level-tau", default="24h",
                    help="the slow level's time constant for --side gains-level (pandas "
                         "Timedelta, default 24h)")
    ap.add_argument("--known", action="store_true",
                    help="also replay with the measured inputs: the served / known-input ratio "
                         "of each run (else from reproduce's results.json beside the model)")
    ap.add_argument("--profile", choices=("train", "file"), default="train",
                    help="the weekly gains profile of the served forecasts: re-estimated from "
                         "the forecast study's training weeks (default; as reproduce's model "
                         "file) or the model file's (zonecast identify's: every whole week, "
                         "the validation weeks' own gains included; the tables before "
                         "2026-12-05)")
    args = ap.parse_args()
    global LEVEL_TAU, KNOWN, PROFILE, DUMP, STREAM, ALL_MIDNIGHTS, ISSUE_WEEKDAYS, FILLS, \
        ISSUE_HOURS
    FILLS = tuple(args.fill)
    KNOWN, PROFILE, DUMP, STREAM = args.known, args.profile, args.dump, args.stream
    ALL_MIDNIGHTS, ISSUE_WEEKDAYS = args.all_midnights, args.issue_weekdays
    ISSUE_HOURS = tuple(args.issue_hours)
    if not all(0 <= h < 24 for h in ISSUE_HOURS):
        ap.error("--issue-hours takes local hours 0..23")
    if ISSUE_HOURS != (0,) and not ALL_MIDNIGHTS:
        ap.error("--issue-hours needs --all-midnights")
    if ALL_MIDNIGHTS and STREAM is None:
        ap.error("--all-midnights needs --stream")
    if ISSUE_WEEKDAYS is not None and not ALL_MIDNIGHTS:
        ap.error("--issue-weekdays needs --all-midnights")
    if args.side == "monday-fill" and PROFILE != "train":
        ap.error("--side monday-fill needs --profile train (the model file's profile is "
                 "filled when it was written)")
    LEVEL_TAU = pd.Timedelta(args.level_tau)
    campaigns = {p.name: p for p in args.extra}
    if args.family is not None:
        doc = json.loads((args.family / "index.json").read_text())
        for m in doc["members"] if isinstance(doc, dict) else doc:
            campaigns[m["name"]] = args.family / m["name"]
    names = [n for n in (args.only or campaigns) if (args.reports / n / "model.json").is_file()]
    if not names:
        raise SystemExit(f"no member of {sorted(campaigns)} has a report in {args.reports}")
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores", flush=True)
    head = {"reheat": ("learned rise", "thermostat's reheat"),
            "cooling": ("reheat, cooling off", "reheat and cooling"),
            "young": ("steady filter", "young filter"),
            "young-std": ("young filter, steady std", "young filter and std"),
            "day-class": ("pooled days", "day classes"),
            "weather-spread": ("model std", "with the weather's spread"),
            "gains-level": ("profile and short offset", f"slow level {LEVEL_TAU}"),
            "spread-sides": ("weather's spread one way", "both ways"),
            "closed-loop": ("model std", "scaled by the thermostats' hold"),
            "monday-fill": (f"empty day: {FILLS[0]}", f"{FILLS[1]}"),
            "deadband": ("learned airflow", "throttled in the dead band"),
            "learn-empty": ("empty bins filled", "and learned online"),
            "after-off": ("working and other days", "and the day after a day off"),
            "aci-feedback": ("level moved by the current interval", "by the served interval"),
            "interval-scale": ("level moved", "a factor moved, level fixed"),
            "settled-calibration": ("calibrated from every start", "from a settled filter"),
            "weather-blend": ("forecast as received", "combined with the recent days"),
            "defaults": ("defaults", "defaults (not run again)")}[args.side]
    print(f"| member | {head[0]} | {head[1]} | / known inputs | coverage (zones) "
          "| working / other days / after a day off | seconds off / on |")
    print("|---|---|---|---|---|---|---|")
    for name in names:
        model = args.reports / name / "model.json"
        on_only = args.on_only and args.side != "defaults"
        off, cov_off, s_off, cls_off = ((None,) * 4 if on_only
                                        else served(campaigns[name], model, False, args.side))
        on, cov_on, s_on, cls_on = ((off, cov_off, s_off, cls_off) if args.side == "defaults"
                                    else served(campaigns[name], model, True, args.side))
        if on_only:  # the off run is known from an earlier run: shown as the on run's
            off, cov_off, s_off, cls_off = on, cov_on, s_on, cls_on
        res = args.reports / name / "results.json"
        known = _find(json.loads(res.read_text()), "service_known_inputs") if res.is_file() \
            else None
        if KNOWN:
            ratio = (f"{off['mean'] / off['known']:.3f} → {on['mean'] / on['known']:.3f} "
                     f"(known {off['known']:.3f} → {on['known']:.3f})")
        else:
            ratio = (f"{off['mean'] / known['mean']:.3f} → {on['mean'] / known['mean']:.3f}"
                     if known else "–")
        zones = [f"{min(c[z] for z in c if z != 'all'):.3f}–"
                 f"{max(c[z] for z in c if z != 'all'):.3f}" for c in (cov_off, cov_on)]
        print(f"| {name} | {off['mean']:.3f} | **{on['mean']:.3f}** | {ratio} | "
              f"{cov_off['all']:.3f} ({zones[0]}) → {cov_on['all']:.3f} ({zones[1]}) | "
              f"{cls_off[0]:.3f} / {cls_off[1]:.3f} / {cls_off[2]:.3f} → "
              f"{cls_on[0]:.3f} / {cls_on[1]:.3f} / {cls_on[2]:.3f} | "
              f"{s_off:.0f} / {s_on:.0f} |", flush=True)


if __name__ == "__main__":
    main()
