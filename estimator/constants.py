"""Constants shared by the estimator, the jobs and the service: the model step, the forecast
horizon, interval quantiles and the default filter noise.

One home for each number; modules import them from here (docs/architecture.md).
"""

from __future__ import annotations

import pandas as pd

__all__ = [
    "DAYAHEAD_TAU",
    "DAYAHEAD_WINDOW",
    "HORIZON",
    "MAX_GAP",
    "SIGMA_AIR_FORECAST",
    "SIGMA_AIR_ONLINE",
    "SIGMA_AIR_X0",
    "SIGMA_MEAS",
    "SIGMA_WALL_FORECAST",
    "STEP",
    "STEPS_PER_DAY",
    "STEPS_PER_WEEK",
    "STEP_S",
    "Z90",
]

#: model step of the paper [s] (paper eq:model_dt: 15 min)
STEP_S = 900.0
#: the same step as a pandas Timedelta (telemetry grids, time-of-week bins)
STEP = pd.Timedelta(seconds=STEP_S)
#: steps of a day and of a week on the model step
STEPS_PER_DAY = int(pd.Timedelta("1D") / STEP)
STEPS_PER_WEEK = 7 * STEPS_PER_DAY
#: forecast horizon [steps]: 96 x 15 min = 24 h (paper section 5)
HORIZON = STEPS_PER_DAY
#: standard normal 95 % quantile: the two-sided 90 % interval is mean +- Z90 std
Z90 = 1.6448536269514722

#: measurement noise of a zone temperature [K] (filters and forecast intervals)
SIGMA_MEAS = 0.2
#: air-state process noise propagated over a forecast [K per step]
SIGMA_AIR_FORECAST = 0.3
#: element-state process noise [K per step]: heavy elements move slowly
SIGMA_WALL_FORECAST = 0.01
#: air-state process noise of the filter that estimates x(0) before an identification
#: weekend and of the forecasts' day filter [K per step]: it covers the unmodelled internal
#: gains of a day of operation (docs/identification.md)
SIGMA_AIR_X0 = 3.0
#: air-state process noise of the online filter [K per step]: lets the air states follow
#: the measurements, which keeps the per-step f_IG estimate unbiased (docs/numerics.md)
SIGMA_AIR_ONLINE = 0.3

#: day-ahead gains offset: decay time and averaging window (chosen on the training weeks)
DAYAHEAD_TAU = pd.Timedelta("1h")
DAYAHEAD_WINDOW = pd.Timedelta("1h")
#: longest stretch without data the online filter bridges by prediction
MAX_GAP = pd.Timedelta("6h")
