"""The per-step least squares of paper Eq:ig(k-1) recovers injected internal gains."""

import numpy as np
import pandas as pd
import pytest
from zonecast.estimator.dataset import ModelData
from zonecast.estimator.integrate import ExactStepper
from zonecast.estimator.internal_gains import (
    stepper_for,
    track_gains,
    truth_column,
    truth_correlation,
    zone_gain_heat,
)
from zonecast.estimator.rc.network import ModelOptions as _Options
from zonecast.estimator.telemetry import segments_of

#: the RC network alone (NREL's files' scheduled inputs, infiltration and ground, add to u)
# the paper's structure of the 5-zone: no infiltration, ground, shading or return air
NO_LEAK = _Options(infiltration="none", ground="adiabatic", shading="none", return_air="none")

ZONES = {"South": ["SPACE1-1"], "East": ["SPACE2-1"], "North": ["SPACE3-1"],
         "West": ["SPACE4-1"], "Core": ["SPACE5-1"]}


@pytest.fixture(scope="module")
def model(five_zone):
    from zonecast.estimator.model import build_model
    return build_model(five_zone, ZONES, {f"VAV-{i}": f"SPACE{i}-1" for i in range(1, 6)},
                       options=NO_LEAK)


def _data(model, n=2 * 96, seed=1):
    rng = np.random.default_rng(seed)
    times = pd.date_range("2015-04-13", periods=n, freq="15min", tz="UTC")
    u = np.repeat(rng.uniform(0.05, 0.5, (n // 4, 5)), 4, axis=0)
    day = np.arange(n) / 96
    v = np.column_stack([14 + 4 * np.sin(2 * np.pi * day), np.full(n, 13.0),
                         np.zeros((n, 5)) + 100 * (np.sin(2 * np.pi * day) > 0)[:, None]])
    f_true = np.clip(20 * np.sin(2 * np.pi * (day - 0.3)), 0, None)[:, None] * rng.uniform(0.5, 1.5, 5)
    x0 = model.steady_state(u[0], v[0])
    sim = model.simulate(x0, u, v, f_true)
    d = ModelData(times, u, v, sim.y[:-1], list(ZONES), [f"VAV-{i}" for i in range(1, 6)],
                  segments_of(times, pd.Timedelta("15min")), np.zeros(n, bool), "UTC")
    return d, f_true, x0, sim


def test_recovers_an_injected_gain_profile(model):
    d, f_true, x0, sim = _data(model)
    tr = track_gains(model, d, 0, len(d) - 1, x0)
    np.testing.assert_allclose(tr.f_ig, f_true[:-1], atol=1e-6)
    np.testing.assert_allclose(tr.x, sim.x[:-1], atol=1e-8)


def test_missing_rows_hold_the_last_estimate(model):
    d, _f_true, x0, _ = _data(model)
    d.y[50] = np.nan
    tr = track_gains(model, d, 0, 100, x0)
    np.testing.assert_allclose(tr.f_ig[49], tr.f_ig[48])   # y(50) missing -> f(49) held


def test_stepper_refuses_airflow_above_its_bound(model):
    d, *_ = _data(model)
    st = stepper_for(model, d.u)
    assert isinstance(st, ExactStepper)
    with pytest.raises(ValueError, match="airflow above the stepper's u_max"):
        st.step(np.zeros(model.n), d.u.max(axis=0) * 2, np.zeros(model.n), 13.0)


def test_truth_correlation_and_heat():
    est = np.array([1.0, 2.0, 3.0, np.nan, 5.0])
    assert truth_correlation(est, 2 * est) == {"r": pytest.approx(1.0), "scale": pytest.approx(2.0),
                                               "n": 4}
    np.testing.assert_allclose(zone_gain_heat([[1.0, 2.0]], [3.0, 4.0], [10.0, 20.0]), [[40.0, 120.0]])


def test_truth_column_takes_the_peoples_sensible_heat_where_the_campaign_has_it():
    new = ["people:zone:N", "people_sensible:zone:N", "lights:zone:N"]
    assert truth_column(new, "people", "zone:N") == "people_sensible:zone:N"
    assert truth_column(new, "lights", "zone:N") == "lights:zone:N"
    # a campaign written before the column: the total, as it was
    assert truth_column(["people:zone:N"], "people", "zone:N") == "people:zone:N"
