import numpy as np
import pytest
from zonecast.estimator.evaluate import horizon_rms, rms_by_zone


def test_rms_by_zone_ignores_missing_and_averages_zones():
    meas = np.array([[20.0, 21.0], [20.0, np.nan], [20.0, 21.0]])
    pred = np.array([[21.0, 21.0], [19.0, 30.0], [20.0, 23.0]])
    r = rms_by_zone(pred, meas, ["A", "B"])
    assert r["A"] == pytest.approx(np.sqrt(2 / 3))
    assert r["B"] == pytest.approx(np.sqrt(2.0))
    assert r["mean"] == pytest.approx((r["A"] + r["B"]) / 2)


def test_horizon_rms_per_lead():
    meas = np.zeros((2, 3, 1))
    pred = np.array([[[0.0], [1.0], [2.0]], [[0.0], [1.0], [np.nan]]])
    h = horizon_rms(pred, meas, ["A"])
    assert h["A"] == pytest.approx([0.0, 1.0, 2.0])


def test_shape_errors_say_what_is_expected():
    with pytest.raises(ValueError, match=r"must both be \(N, 2\)"):
        rms_by_zone(np.zeros((3, 2)), np.zeros((3, 3)), ["A", "B"])
