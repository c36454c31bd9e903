"""Identification recovers known parameters from data simulated by the model itself."""

import dataclasses

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from zonecast.estimator.dataset import ModelData
from zonecast.estimator.identify import (
    IdentificationError,
    IdentificationResult,
    _Problem,
    identify,
    weekend_spans,
)
from zonecast.estimator.rc.network import ModelOptions as _Options
from zonecast.estimator.telemetry import segments_of

#: the RC network alone (NREL's files' scheduled inputs, infiltration and ground, add to u)
# the paper's structure of the 5-zone: no infiltration, ground, shading or return air
NO_LEAK = _Options(infiltration="none", ground="adiabatic", shading="none", return_air="none")


def _model_and_inputs(five_zone, seed, options=NO_LEAK):
    """The five-zone model (``options``) and three days of inputs (2-h airflow blocks, a
    sunny day)."""
    from zonecast.estimator.model import build_model

    zones = {"South": ["SPACE1-1"], "East": ["SPACE2-1"], "North": ["SPACE3-1"],
             "West": ["SPACE4-1"], "Core": ["SPACE5-1"]}
    boxes = {f"VAV-{i}": f"SPACE{i}-1" for i in range(1, 6)}
    model = build_model(five_zone, zones, boxes, options=options)
    rng = np.random.default_rng(seed)
    times = pd.date_range("2015-04-17 00:00", periods=3 * 96, freq="15min",
                          tz="America/Los_Angeles").tz_convert("UTC")
    n = len(times)
    u = np.repeat(rng.uniform(0.05, 0.6, (n // 8, 5)), 8, axis=0)      # 2-h blocks
    day = np.arange(n) / 96.0
    sun = np.clip(600 * np.sin(2 * np.pi * (day - 0.25)), 0, None)
    v = np.column_stack([15 + 5 * np.sin(2 * np.pi * (day - 0.375)), np.full(n, 13.5),
                         0.6 * sun, sun, 0.6 * sun, 0.2 * sun, 1.3 * sun])
    return model, zones, boxes, rng, times, u, v, day


@pytest.fixture(scope="module")
def truth_and_data(five_zone):
    model, zones, boxes, rng, times, u, v, _ = _model_and_inputs(five_zone, 5)
    n = len(times)
    true = model.params.start_params.copy()
    names = model.params.param_names
    true[names.index("gamma_IW")] *= 1.6
    true[names.index("U_win")] *= 0.7
    for z in zones:
        true[names.index(f"c_IG[{z}]")] = {"South": 6.0, "East": 3.0, "North": 1.0,
                                           "West": 4.0, "Core": 9.0}[z]
    truth = model.with_params(true)
    x0 = truth.steady_state(u[0], v[0])
    sim = truth.simulate(x0, u, v)
    y = sim.y[:-1] + rng.normal(0.0, 0.05, (n, 5))
    data = ModelData(times, u, v, y, list(zones), list(boxes), segments_of(times, pd.Timedelta("15min")),
                     np.zeros(n, bool), "America/Los_Angeles")
    return model, true, data


def test_recovers_known_parameters(truth_and_data):
    model, true, data = truth_and_data
    res = identify(model, data, train=["2015-04-18"], n_starts=1, max_nfev=40)
    names = res.param_names
    # the fit reproduces the data to the noise level (sigma 0.05 degC)
    assert res.train_rms["mean"] < 0.08
    # well-excited parameters come back within 15 %; every estimate within 4 stderr of truth
    for p in ("gamma_IW", "c_IG[Core]", "c_IG[South]"):
        i = names.index(p)
        assert res.params[i] == pytest.approx(true[i], rel=0.15), p
    assert res.to_dict()["table2"]["training"]["mean"] == res.train_rms["mean"]
    # the plotted weekend simulations are the ones Table 2 scores
    from zonecast.estimator.evaluate import rms_by_zone
    from zonecast.estimator.identify import weekend_simulations
    sims = weekend_simulations(model.with_params(res.params), data, ["2015-04-18"])
    assert len(sims) == 1 and sims[0]["saturday"] == "2015-04-18"
    rms = rms_by_zone(sims[0]["simulated"], sims[0]["measured"], data.zones)
    assert rms["mean"] == pytest.approx(res.train_rms["mean"], rel=1e-9)
    assert res.corr.shape == (len(names), len(names))
    np.testing.assert_allclose(np.diag(res.corr)[res.stderr > 0], 1.0, atol=1e-9)


def test_weekend_needs_a_saturday_and_data(truth_and_data):
    _, _, data = truth_and_data
    with pytest.raises(IdentificationError, match="is not a Saturday"):
        weekend_spans(data, ["2015-04-17"])
    with pytest.raises(IdentificationError, match="no telemetry for the weekend"):
        weekend_spans(data, ["2015-05-02"])


def test_weekend_needs_the_day_before(truth_and_data):
    model, _, data = truth_and_data
    late = data.rows(slice(96, None))       # starts on the Saturday itself
    with pytest.raises(IdentificationError, match="needs the 24 h before it"):
        identify(model, late, train=["2015-04-18"], n_starts=1)


def test_a_weekend_at_a_segment_end_is_not_scored_against_the_next_segment(truth_and_data):
    """Issue 13 item 3: the last simulated row of a weekend that ends its data segment has no
    measurement (the next row is the first of a later week); it must not enter the fit or
    Table 2."""
    from zonecast.estimator.identify import measured_rows, weekend_simulations

    model, _, data = truth_and_data
    alone = data.rows(slice(None))
    later = data.times + pd.Timedelta(days=14)
    times = data.times.append(later)
    y2 = np.vstack([data.y, data.y + 40.0])  # the later week is far off: it must not count
    two = ModelData(times, np.vstack([data.u, data.u]), np.vstack([data.v, data.v]), y2,
                    data.zones, data.boxes, segments_of(times, pd.Timedelta("15min")),
                    np.zeros(len(times), bool), data.timezone)
    assert len(two.segments) == 2
    (a, b), = weekend_spans(two, ["2015-04-18"])
    assert b == two.segments[0][1]  # the weekend ends the first segment
    assert measured_rows(two, a, b) == slice(a + 1, b)
    assert measured_rows(two, a, b - 1) == slice(a + 1, b)  # inside a segment: a+1 ... b
    fitted = model.with_params(model.params.start_params)
    s1 = weekend_simulations(fitted, alone, ["2015-04-18"])[0]
    s2 = weekend_simulations(fitted, two, ["2015-04-18"])[0]
    assert len(s2["measured"]) == b - a - 1 and s2["times"][-1] < later[0]
    np.testing.assert_array_equal(s1["measured"], s2["measured"])
    r1 = identify(model, alone, train=["2015-04-18"], n_starts=1, max_nfev=3)
    r2 = identify(model, two, train=["2015-04-18"], n_starts=1, max_nfev=3)
    np.testing.assert_array_equal(r1.params, r2.params)
    assert r2.train_rms["mean"] == r1.train_rms["mean"] < 1.0


def test_results_object_in_the_statsmodels_manner(truth_and_data):
    model, _, data = truth_and_data
    res = identify(model, data, train=["2015-04-18"], n_starts=1, max_nfev=5)
    names = res.param_names
    assert res.bse is res.stderr
    cov = res.cov_params()
    np.testing.assert_allclose(cov, cov.T, atol=1e-12)
    np.testing.assert_allclose(np.diag(cov), res.bse ** 2, rtol=1e-9)
    assert res.model is not None and np.array_equal(res.model.params.values, res.params)
    assert 1 <= res.rank <= len(names) and res.condition >= 1.0
    assert len(res.bounds) == len(names)
    # a parameter pinned at its bound is named, in the summary too
    i = names.index("gamma_IW")
    pinned = IdentificationResult(**{**res.__dict__, "params": res.params.copy()})
    pinned.params[i] = res.bounds[i][1]
    assert "gamma_IW" in pinned.at_bounds() and "gamma_IW" not in res.at_bounds()
    text = pinned.summary()
    assert "gamma_IW" in text.split("at a bound")[-1] and "Jacobian rank" in text
    d = pinned.to_dict()
    assert d["at_bounds"] == pinned.at_bounds() and d["jacobian_rank"] == res.rank
    # the films of regular operation: the factors, or the test that kept the identified ones
    assert "regular operation" not in text and d["operating_films_test"] is None
    pinned.operating_films = {"gamma_floor": 1 / 1.30}
    pinned.operating_films_test = {"k_mean": 0.21, "stderr": 0.03, "min_t": 3.0,
                                   "applied": True}
    assert "gamma_floor x0.769 of the identified" in pinned.summary()
    assert pinned.to_dict()["operating_films_test"]["applied"] is True
    pinned.operating_films = None
    pinned.operating_films_test = {"k_mean": -0.05, "stderr": 0.03, "min_t": 3.0,
                                   "applied": False}
    assert "the identified ones (the reheat leak at them, k -0.050 +- 0.030" in pinned.summary()


def test_map_identification_holds_parameters_to_their_priors(truth_and_data, five_zone):
    """A tight prior at the truth pulls every estimate there; a prior far off the truth on a
    well-determined parameter does not (the data win); the result reports the prior."""
    from zonecast.estimator.priors import Prior, building_priors, prior_residuals

    model, true, data = truth_and_data
    names = model.params.param_names
    tight = {n: Prior(float(v), 1e-3 * max(abs(v), 1.0), "test") for n, v in zip(names, true)}
    res = identify(model, data, train=["2015-04-18"], n_starts=1, max_nfev=20, priors=tight,
                   sigma_e=0.3)
    np.testing.assert_allclose(res.params, true, rtol=2e-2, atol=2e-2)
    assert res.priors == tight and res.to_dict()["prior"]["U_win"]["source"] == "test"
    assert "prior" in res.summary()
    # a weak prior far from the truth on gamma_IW (well excited): the data win
    weak = building_priors(model.params, five_zone)
    i = names.index("gamma_IW")
    weak["gamma_IW"] = Prior(3.0 * true[i], 0.5 * true[i], "test, far off")
    res = identify(model, data, train=["2015-04-18"], n_starts=1, max_nfev=40, priors=weak,
                   sigma_e=0.05)
    assert res.params[i] == pytest.approx(true[i], rel=0.2)
    assert prior_residuals(true, weak, names, 0.3)[i] == pytest.approx(-0.3 * 4.0)


def test_building_priors_take_window_u_and_shgc_from_the_idf(five_zone):
    from zonecast.estimator.model import build_model
    from zonecast.estimator.priors import building_priors

    model = build_model(five_zone, {"South": ["SPACE1-1"]}, {"VAV-1": "SPACE1-1"},
                        options=NO_LEAK)
    pri = building_priors(model.params, five_zone)
    assert list(pri) == model.params.param_names
    assert all(p.sd > 0 for p in pri.values())
    wins = [w for w in five_zone.windows.values() if w.u_value is not None]
    if wins:  # simple glazing systems carry U and SHGC
        assert "IDF" in pri["U_win"].source
    else:
        assert pri["U_win"].mean == 2.8
    # films as convection alone (a model with interior long-wave exchange): their own priors
    conv = building_priors(model.params, five_zone, convective=True)
    assert conv["gamma_IW"].mean == pytest.approx(3.1) and conv["gamma_ceil"].mean < 4.1
    assert conv["U_win"] == pri["U_win"] and pri["gamma_IW"].mean == pytest.approx(8.3)
    # gamma_absorp centred on the exterior walls' own outer solar absorptance (by area)
    walls = [s for s in five_zone.surfaces.values() if s.boundary == "Outdoors"
             and s.surface_type.lower() == "wall" and s.area > 0]
    absorp = [five_zone.constructions[s.construction].layers[0].solar_absorptance
              for s in walls]
    expected = np.dot(absorp, [s.area for s in walls]) / sum(s.area for s in walls)
    assert pri["gamma_absorp"].mean == pytest.approx(expected)
    assert pri["gamma_absorp"].mean != 0.6 and "exterior walls" in pri["gamma_absorp"].source
    assert building_priors(model.params)["gamma_absorp"].mean == 0.6  # no building: handbook


def test_film_priors_follow_the_idf_inside_convection_algorithm(five_zone, small_office):
    from zonecast.estimator.model import build_model
    from zonecast.estimator.priors import (
        CONVECTIVE_FILMS,
        TARP_FILMS,
        building_priors,
        convective_films,
    )

    # the files' own SurfaceConvectionAlgorithm:Inside (TARP is EnergyPlus's default)
    assert five_zone.inside_convection == "Simple"
    assert small_office.inside_convection == "TARP"
    assert convective_films(five_zone) == CONVECTIVE_FILMS
    assert convective_films(None) == CONVECTIVE_FILMS
    tarp = convective_films(small_office)
    assert {k: v[:2] for k, v in tarp.items()} == {k: v[:2] for k, v in TARP_FILMS.items()}
    assert all("TARP" in v[2] for v in tarp.values())
    # Walton's coefficients at 1 K: about half of EnergyPlus's Simple constants
    assert TARP_FILMS["gamma_IW"][0] == pytest.approx(1.31, abs=0.02)
    assert TARP_FILMS["gamma_floor"][0] == pytest.approx((1.52 + 0.76) / 2, abs=0.05)
    for k in TARP_FILMS:
        rel = TARP_FILMS[k][1] / TARP_FILMS[k][0]
        assert rel == pytest.approx(CONVECTIVE_FILMS[k][1] / CONVECTIVE_FILMS[k][0], abs=0.12)
    model = build_model(five_zone, {"South": ["SPACE1-1"]}, {"VAV-1": "SPACE1-1"},
                        options=NO_LEAK)
    pri = building_priors(model.params, small_office, convective="idf")
    assert pri["gamma_IW"].mean == TARP_FILMS["gamma_IW"][0]
    assert building_priors(model.params, five_zone, convective="idf")["gamma_IW"].mean == \
        CONVECTIVE_FILMS["gamma_IW"][0]
    # convective=True keeps the Simple constants whatever the file says
    assert building_priors(model.params, small_office, convective=True)["gamma_IW"].mean == \
        CONVECTIVE_FILMS["gamma_IW"][0]


def test_operating_films_follow_the_idf_inside_convection_algorithm(five_zone, small_office):
    """The films of regular operation: the experiments' films scaled down for a
    natural-convection algorithm (TARP), unchanged for EnergyPlus's constant Simple films,
    without a building or with mode "none"; an unknown mode says what to give."""
    from zonecast.estimator.priors import OPERATING_FILMS, operating_film_ratios

    assert operating_film_ratios(small_office) == OPERATING_FILMS
    assert set(OPERATING_FILMS) == {"gamma_floor", "gamma_IW", "gamma_ceil"}
    # a natural film grows with the face-to-air difference, which the experiments make
    # larger than operation: smaller films in operation, the floors' the most
    assert all(0.5 < f < 1.0 for f in OPERATING_FILMS.values())
    assert OPERATING_FILMS["gamma_floor"] < OPERATING_FILMS["gamma_IW"] < \
        OPERATING_FILMS["gamma_ceil"]
    assert operating_film_ratios(five_zone) == {}
    assert operating_film_ratios(None) == {}
    assert operating_film_ratios(small_office, "none") == {}
    with pytest.raises(ValueError, match="operating_films='tarp': use one of 'natural', 'none'"):
        operating_film_ratios(small_office, "tarp")


def test_log_normal_priors_hold_positive_coefficients_away_from_zero(five_zone):
    """positive="log": films and U_win get log-normal priors of the same median and relative
    spread; near the median they weigh a deviation as the Gaussian does, near zero far more,
    and the absorptances and c_IG keep their Gaussians."""
    from zonecast.estimator.model import build_model
    from zonecast.estimator.priors import (
        POSITIVE,
        Prior,
        building_priors,
        prior_jacobian,
        prior_residuals,
    )

    model = build_model(five_zone, {"South": ["SPACE1-1"]}, {"VAV-1": "SPACE1-1"},
                        options=NO_LEAK)
    names = model.params.param_names
    normal = building_priors(model.params, five_zone)
    log = building_priors(model.params, five_zone, positive="log")
    assert {n for n, p in log.items() if p.log} == set(POSITIVE) & set(names)
    assert "gamma_roof" in POSITIVE and "gamma_roof" not in names  # the 5-zone South room
    assert all(log[n].mean == normal[n].mean and log[n].sd == normal[n].sd for n in names)
    mu = np.array([normal[n].mean for n in names])
    i = names.index("gamma_EW")
    near = mu.copy()
    near[i] *= 1.01
    assert prior_residuals(near, log, names, 0.3)[i] == pytest.approx(
        prior_residuals(near, normal, names, 0.3)[i], rel=0.01)
    cut = mu.copy()
    cut[i] = 0.001  # the exterior film at its lower bound
    r_log, r_normal = (prior_residuals(cut, p, names, 0.3)[i] for p in (log, normal))
    assert r_normal == pytest.approx(-0.3 * 25.0 / 12.0, rel=1e-3)
    assert r_log == pytest.approx(0.3 * np.log(0.001 / 25.0) * 25.0 / 12.0)
    assert r_log < 3 * r_normal
    j = names.index("gamma_absorp")
    assert not log["gamma_absorp"].log
    assert prior_residuals(cut, log, names, 0.3)[j] == prior_residuals(cut, normal, names, 0.3)[j]
    with pytest.raises(ValueError, match="depends on theta"):
        prior_jacobian(log, names, 0.3)
    with pytest.raises(ValueError, match="use one of normal, log"):
        building_priors(model.params, five_zone, positive="lognormal")
    with pytest.raises(ValueError, match="positive median"):
        Prior(0.0, 1.0, "test", log=True)


@given(theta=st.lists(st.floats(0.01, 200.0), min_size=5, max_size=5))
@settings(max_examples=40, deadline=None)
def test_log_normal_prior_jacobian_matches_finite_differences(theta):
    """The MAP fit's Jacobian rows of log-normal priors are the residuals' derivatives."""
    from zonecast.estimator.priors import Prior, prior_jacobian, prior_residuals

    names = ["a", "b", "c", "d", "e"]
    priors = {n: Prior(m, 0.5 * m, "test", log=n != "e")
              for n, m in zip(names, (25.0, 3.1, 2.5, 2.5, 1.6))}
    t = np.array(theta)
    jac = prior_jacobian(priors, names, 0.3, t)
    assert np.allclose(jac, np.diag(np.diag(jac)))
    h = 1e-6 * t
    fd = (prior_residuals(t + h, priors, names, 0.3)
          - prior_residuals(t - h, priors, names, 0.3)) / (2 * h)
    assert np.allclose(np.diag(jac), fd, rtol=1e-5)


def test_identification_on_declared_experiments_with_a_lead_in(truth_and_data):
    """Issue 13 item 4: window='experiments' fits the site's declared experiment rows of each
    weekend with 2 h before and after, and says which hours it used."""
    from zonecast.estimator.identify import identification_spans, weekend_simulations

    model, _, data = truth_and_data
    local = data.local_times()
    exc = (local.day_of_week == 5) & (local.hour >= 8) & (local.hour < 20)  # Sat 08-20
    d = ModelData(data.times, data.u, data.v, data.y, data.zones, data.boxes, data.segments,
                  np.asarray(exc), data.timezone)
    (a, b), = identification_spans(d, ["2015-04-18"], "experiments")
    assert local[a].hour == 6 and local[a].day_of_week == 5
    assert local[b - 1].hour == 21 and local[b - 1].minute == 45  # 20:00 + 2 h, exclusive
    assert identification_spans(d, ["2015-04-18"]) == weekend_spans(d, ["2015-04-18"])
    with pytest.raises(IdentificationError, match="no declared experiment"):
        identification_spans(data, ["2015-04-18"], "experiments")
    with pytest.raises(IdentificationError, match="window must be one of"):
        identification_spans(d, ["2015-04-18"], "night")
    res = identify(model, d, train=["2015-04-18"], n_starts=1, max_nfev=5, window="experiments")
    assert res.window == "experiments" and res.n_residuals == (b - a) * len(d.zones)
    assert res.spans == [{"role": "training", "start": "2015-04-18T06:00:00-07:00",
                          "end": "2015-04-18T22:00:00-07:00"}]
    assert "window experiments: 2015-04-18T06:00 to 2015-04-18T22:00" in res.summary()
    sims = weekend_simulations(res.model, d, ["2015-04-18"], window="experiments")
    assert sims[0]["saturday"] == "2015-04-18" and len(sims[0]["measured"]) == b - a


def _weekend_gains_case(five_zone, scale, level):
    """Model, parameter names, true parameters (gamma_IW x 1.6), the gains' per-zone shape
    (``level`` W/m2 x a zone factor, 10:00-17:00 of every day) and the data simulated with
    the shape times ``scale`` per zone as internal gains."""
    def occupied(day):  # weekend occupancy, 10:00-17:00
        return ((day % 1) > 0.4) & ((day % 1) < 0.7)

    return _gains_case(five_zone, 7, occupied, level, scale)


def _gains_case(five_zone, seed, when, level, scale=1.0, options=NO_LEAK):
    """Model (``options``), parameter names, true parameters (gamma_IW x 1.6), per-zone
    gains (``level`` W/m2 x a zone factor where ``when(day)``) and the data simulated with
    them x ``scale``."""
    model, zones, boxes, rng, times, u, v, day = _model_and_inputs(five_zone, seed, options)
    n = len(times)
    true = model.params.start_params.copy()
    names = model.params.param_names
    true[names.index("gamma_IW")] *= 1.6
    truth = model.with_params(true)
    shape = np.where(when(day), level, 0.0)[:, None] * rng.uniform(0.5, 1.5, 5)
    sim = truth.simulate(truth.steady_state(u[0], v[0]), u, v, shape * scale)
    y = sim.y[:-1] + rng.normal(0.0, 0.05, (n, 5))
    data = ModelData(times, u, v, y, list(zones), list(boxes),
                     segments_of(times, pd.Timedelta("15min")), np.zeros(n, bool),
                     "America/Los_Angeles")
    return model, names, true, shape, data


def test_known_weekend_gains_enter_the_fit(five_zone):
    """Data simulated with time-varying gains on the weekend: the paper's fit (f_IG = 0)
    leaves them to the parameters and misses; the fit told the gains (``f_ig``) recovers
    the parameters and reaches the noise level, from the given start."""
    model, names, true, f_ig, data = _weekend_gains_case(five_zone, np.ones(5), 12.0)
    blind = identify(model, data, train=["2015-04-18"], n_starts=1, max_nfev=40)
    told = identify(model, data, train=["2015-04-18"], max_nfev=40, f_ig=f_ig,
                    start=blind.params)
    assert len(told.starts) == 1 and told.starts[0]["start"] == list(blind.params)
    assert told.train_rms["mean"] < 0.08 < blind.train_rms["mean"]
    # the plotted simulations with those gains are the ones Table 2 scores
    from zonecast.estimator.evaluate import rms_by_zone
    from zonecast.estimator.identify import weekend_simulations
    sim = weekend_simulations(told.model, data, ["2015-04-18"], f_ig=f_ig)[0]
    assert rms_by_zone(sim["simulated"], sim["measured"], data.zones)["mean"] == \
        pytest.approx(told.train_rms["mean"], rel=1e-9)
    i = names.index("gamma_IW")
    assert told.params[i] == pytest.approx(true[i], rel=0.15)


def test_a_given_start_comes_first_and_drawn_starts_follow(truth_and_data):
    model, _, data = truth_and_data
    x = model.params.start_params * 1.1
    res = identify(model, data, train=["2015-04-18"], n_starts=2, max_nfev=2, agree_rtol=0,
                   start=x)
    assert len(res.starts) == 2 and res.starts[0]["start"] == pytest.approx(list(x))
    assert res.starts[1]["start"] != pytest.approx(list(x))


def test_starts_stop_once_two_agree(truth_and_data):
    """Two starts that reach the same cost end the multi-start (the third is skipped) with
    the optimum every start finds; ``agree_rtol=0`` runs every start."""
    model, _, data = truth_and_data
    msgs = []
    early = identify(model, data, train=["2015-04-18"], n_starts=3, max_nfev=40,
                     agree_rtol=1e-3, progress=msgs.append)
    full = identify(model, data, train=["2015-04-18"], n_starts=3, max_nfev=40, agree_rtol=0.0)
    assert len(full.starts) == 3
    first_two = sorted(s["cost"] for s in full.starts[:2])
    assert first_two[1] - first_two[0] <= 1e-3 * first_two[0]   # this problem has one optimum
    assert len(early.starts) == 2 and any("1 skipped" in m for m in msgs)
    assert early.n_evaluations < full.n_evaluations
    assert early.train_rms["mean"] == pytest.approx(full.train_rms["mean"], rel=1e-2)


def test_gain_columns_of_the_jacobian_are_exact(truth_and_data):
    """The Jacobian's c_IG columns (one block run of every zone's constant gain) equal the
    residuals' change for a unit change of each c_IG (the zone temperatures are affine in
    it), also with a missing measurement; the physical columns stay forward differences."""
    model, _, data = truth_and_data
    spans = weekend_spans(data, ["2015-04-18"])
    y = data.y.copy()
    y[spans[0][0] + 10:spans[0][0] + 14, 1] = np.nan
    data = ModelData(data.times, data.u, data.v, y, data.zones, data.boxes, data.segments,
                     data.excitation, data.timezone)
    prob = _Problem(model, data, spans, [np.full(model.n, 21.0)])
    theta = model.params.values
    L = 1.02 * prob.bound(theta)
    f0 = prob.residuals(theta, L)
    G = prob.gain_columns(theta, L)
    for z in range(G.shape[1]):
        t = theta.copy()
        t[prob.n_phys + z] += 1.0
        np.testing.assert_allclose(G[:, z], prob.residuals(t, L) - f0, rtol=0, atol=1e-12)
    lo, hi = (np.array(b) for b in zip(*model.params.bounds))
    J = prob.jacobian(theta, lo, hi)
    assert J.shape == (len(f0), len(theta))
    np.testing.assert_array_equal(J[:, prob.n_phys:], G)


def _assert_gain_columns_exact(prob, theta, m):
    """The ``m`` gain columns of the Jacobian (c_IG and the shapes' scales) equal the
    residuals' change for a unit change of each (the zone temperatures are affine in them)."""
    L = 1.02 * prob.bound(theta)
    f0 = prob.residuals(theta, L)
    G = prob.gain_columns(theta, L)
    assert G.shape == (len(f0), m)
    for j in range(m):
        t = theta.copy()
        t[prob.n_phys + j] += 1.0
        np.testing.assert_allclose(G[:, j], prob.residuals(t, L) - f0, rtol=0, atol=1e-12)


def test_gain_shape_scales_are_exact_columns_and_recovered(five_zone):
    """Weekend gains 1.5 x a known per-zone shape in zones 0-2 and none in zones 3-4: the
    fit with the shape (``gain_shape``) finds those scales, a Table 2 at the noise level
    and the parameters; the scales' Jacobian columns equal unit changes of the scales."""
    scale = np.array([1.5, 1.5, 1.5, 0.0, 0.0])
    model, names, true, shape, data = _weekend_gains_case(five_zone, scale, 10.0)
    zones = data.zones
    with pytest.raises(IdentificationError, match="one value per row and zone"):
        identify(model, data, train=["2015-04-18"], gain_shape=shape[:, :2])
    res = identify(model, data, train=["2015-04-18"], max_nfev=40, gain_shape=shape)
    assert len(res.params) == len(names) and set(res.gain_scale) == set(zones)
    got = np.array([res.gain_scale[z]["value"] for z in zones])
    np.testing.assert_allclose(got, scale, atol=0.15)
    assert res.train_rms["mean"] < 0.08
    i = names.index("gamma_IW")
    assert res.params[i] == pytest.approx(true[i], rel=0.15)
    assert res.to_dict()["gain_scale"][zones[0]]["value"] == pytest.approx(got[0])

    spans = weekend_spans(data, ["2015-04-18"])
    prob = _Problem(model, data, spans, [np.full(model.n, 21.0)], shape=shape)
    theta = np.r_[model.params.values, np.ones(5)]
    _assert_gain_columns_exact(prob, theta, 10)


def test_each_weekend_days_scale_is_fitted_and_its_columns_are_exact(five_zone):
    """People in on Saturday (1.8 x the shape) and not on Sunday (0.2 x): one scale for
    both days cannot follow them; with ``day_scale_sd`` each day's deviation is fitted (the
    day columns exact, zero outside their day), Table 2 reaches the noise level and the
    scales recover both days; the validation rows would take the zones' base scale."""
    from zonecast.estimator.identify import _day_shapes
    from zonecast.estimator.priors import building_priors

    model, zones, boxes, rng, times, u, v, day = _model_and_inputs(five_zone, 8)
    n = len(times)
    true = model.params.start_params.copy()
    truth = model.with_params(true)
    shape = np.where(((day % 1) > 0.4) & ((day % 1) < 0.7), 10.0, 0.0)[:, None] \
        * rng.uniform(0.5, 1.5, 5)
    local = times.tz_convert("America/Los_Angeles")
    per_day = np.where(np.asarray(local.day_of_week == 5), 1.8,
                       np.where(np.asarray(local.day_of_week == 6), 0.2, 1.0))
    sim = truth.simulate(truth.steady_state(u[0], v[0]), u, v, shape * per_day[:, None])
    y = sim.y[:-1] + rng.normal(0.0, 0.05, (n, 5))
    data = ModelData(times, u, v, y, list(zones), list(boxes),
                     segments_of(times, pd.Timedelta("15min")), np.zeros(n, bool),
                     "America/Los_Angeles")
    spans = weekend_spans(data, ["2015-04-18"])
    cols, zmap, names = _day_shapes(data, shape, spans)
    assert cols.shape == (n, 15) and list(zmap) == [0, 1, 2, 3, 4] * 3
    assert names[0] == "ds_IG[South,2015-04-18]" and names[5] == "ds_IG[South,2015-04-19]"
    friday = np.asarray(local.day_of_week == 4)
    assert not cols[friday, 5:].any()
    np.testing.assert_allclose(cols[:, 5:10] + cols[:, 10:], np.where(friday[:, None], 0.0,
                                                                      shape), rtol=0, atol=0)
    priors = building_priors(model.params, five_zone)
    with pytest.raises(IdentificationError, match="day_scale_sd needs a gains shape"):
        identify(model, data, train=["2015-04-18"], day_scale_sd=1.0, priors=priors)
    with pytest.raises(IdentificationError, match="day_scale_sd needs a gains shape"):
        identify(model, data, train=["2015-04-18"], day_scale_sd=1.0, gain_shape=shape)
    one = identify(model, data, train=["2015-04-18"], max_nfev=40, gain_shape=shape,
                   priors=priors, sigma_e=0.05, start=true)
    each = identify(model, data, train=["2015-04-18"], max_nfev=40, gain_shape=shape,
                    priors=priors, sigma_e=0.05, start=true, day_scale_sd=1.0)
    assert each.train_rms["mean"] < 0.08 < one.train_rms["mean"]
    assert len(each.params) == len(true)                      # the scales are not the model's
    sat = [each.gain_scale[z]["value"] + each.gain_day_scale[f"{z},2015-04-18"]["value"]
           for z in zones]
    sun = [each.gain_scale[z]["value"] + each.gain_day_scale[f"{z},2015-04-19"]["value"]
           for z in zones]
    np.testing.assert_allclose(sat, 1.8, atol=0.2)
    np.testing.assert_allclose(sun, 0.2, atol=0.2)
    assert each.to_dict()["gain_day_scale"]["South,2015-04-18"]["value"] == pytest.approx(
        each.gain_day_scale["South,2015-04-18"]["value"])

    prob = _Problem(model, data, spans, [np.full(model.n, 21.0)], shape=cols, shape_zones=zmap)
    theta = np.r_[model.params.values, np.ones(5), rng.normal(0.0, 0.5, 10)]
    _assert_gain_columns_exact(prob, theta, 20)


def test_the_x0_filter_told_the_days_gains_starts_the_weekend_right(five_zone):
    """Data simulated with office gains on the Friday before the weekend only: the x(0)
    filter with f_IG = 0 leaves the walls cooler than they are and the weekend misfits;
    told those gains (``x0_gains``, the filter alone: the weekend keeps f_IG = 0) the fit
    reaches the noise and recovers gamma_IW. The plotted simulations with the same x(0)
    options are the ones Table 2 scores; the result records them; a window longer than the
    telemetry before the weekend is refused, saying so."""
    from zonecast.estimator.evaluate import rms_by_zone
    from zonecast.estimator.identify import weekend_simulations

    def friday(day):  # 08:00-18:00 of the first day, the Friday
        return (day < 1) & ((day % 1) > 1 / 3) & ((day % 1) < 0.75)

    model, names, true, gains, data = _gains_case(five_zone, 9, friday, 25.0)
    blind = identify(model, data, train=["2015-04-18"], max_nfev=40)
    told = identify(model, data, train=["2015-04-18"], max_nfev=40, x0_gains=gains,
                    start=blind.params)
    assert told.train_rms["mean"] < 0.08 < blind.train_rms["mean"]
    assert told.x0_gains and not blind.x0_gains and told.x0_window == 96
    assert told.to_dict()["x0_gains"] is True
    i = names.index("gamma_IW")
    assert told.params[i] == pytest.approx(true[i], rel=0.15)
    sim = weekend_simulations(told.model, data, ["2015-04-18"], x0_gains=gains)[0]
    assert rms_by_zone(sim["simulated"], sim["measured"], data.zones)["mean"] == \
        pytest.approx(told.train_rms["mean"], rel=1e-9)
    with pytest.raises(IdentificationError, match="needs the 48 h before it"):
        identify(model, data, train=["2015-04-18"], x0_gains=gains, x0_window=2 * 96)
    with pytest.raises(IdentificationError, match="x0_gains has shape"):
        identify(model, data, train=["2015-04-18"], x0_gains=gains[:10])


def test_x0_offset_columns_of_the_jacobian_are_exact(truth_and_data):
    """The x(0) offsets' Jacobian columns (free responses from each zone's slow states)
    equal the residuals' change for a unit offset of each zone (the zone temperatures are
    affine in x(0)), over two spans at once; the air states carry no offset."""
    from zonecast.estimator.identify import slow_state_basis

    model, _, data = truth_and_data
    basis = slow_state_basis(model)
    assert basis.shape == (model.n, model.n_zones)
    assert not basis[model.structure.air_states()].any()
    assert (basis.sum(axis=1) <= 1).all() and basis.any(axis=0).all()
    a, b = weekend_spans(data, ["2015-04-18"])[0]
    spans = [(a, a + 96), (a + 96, b)]
    prob = _Problem(model, data, spans, [np.full(model.n, 21.0), np.full(model.n, 20.0)],
                    x0_basis=basis)
    theta = np.r_[model.params.values, np.zeros(model.n_zones)]
    L = 1.02 * prob.bound(theta)
    f0 = prob.residuals(theta, L)
    D = prob.offset_columns(theta, L)
    assert D.shape == (len(f0), model.n_zones)
    for z in range(model.n_zones):
        t = theta.copy()
        t[len(model.params.values) + z] += 1.0
        np.testing.assert_allclose(D[:, z], prob.residuals(t, L) - f0, rtol=0, atol=1e-10)
    lo, hi = (np.array(b) for b in zip(*model.params.bounds))
    J = prob.jacobian(theta, np.r_[lo, -np.ones(5)], np.r_[hi, np.ones(5)])
    np.testing.assert_array_equal(J[:, -model.n_zones:], D)


def test_the_x0_filters_bias_in_the_slow_states_is_fitted(five_zone):
    """Office gains on the Friday before the weekend: the x(0) filter (f_IG = 0) leaves the
    walls cooler than they are. With the zones' slow-state offsets fitted (``x0_offset_sd``)
    they come out positive, the fit is closer to the noise and gamma_IW nearer its truth;
    Table 2 and the plotted simulations start from x_KF(0) plus the offsets; the model's
    parameters stay the 13; a fit without priors is refused, saying why.

    The case is built with the roof's film fitted as gamma_EW (``roof_exterior=
    "absorptance"``, the default when it was written). With the balance's known roof film
    (the default since 2026-12-07) the blind fit still misses by more than 0.09 K, but its
    gamma_IW lands within 2 % of the truth, so that case no longer shows the bias."""
    from zonecast.estimator.evaluate import rms_by_zone
    from zonecast.estimator.identify import weekend_simulations
    from zonecast.estimator.priors import building_priors

    def friday(day):
        return (day < 1) & ((day % 1) > 1 / 3) & ((day % 1) < 0.75)

    model, names, true, _, data = _gains_case(
        five_zone, 9, friday, 25.0,
        options=dataclasses.replace(NO_LEAK, roof_exterior="absorptance"))
    priors = building_priors(model.params, five_zone)
    blind = identify(model, data, train=["2015-04-18"], max_nfev=40, priors=priors,
                     sigma_e=0.05)
    fitted = identify(model, data, train=["2015-04-18"], max_nfev=40, priors=priors,
                      sigma_e=0.05, x0_offset_sd=1.0, start=blind.params)
    # blind: 0.11 K and gamma_IW 25 % low; with the offsets: the noise (0.05 K), within 10 %
    assert fitted.train_rms["mean"] < 0.06
    assert blind.train_rms["mean"] > 0.09
    i = names.index("gamma_IW")
    assert fitted.params[i] == pytest.approx(true[i], rel=0.1)
    assert abs(blind.params[i] - true[i]) > 2 * abs(fitted.params[i] - true[i])
    off = fitted.x0_offset()
    assert off.shape == (5,) and (off > 0.2).all()
    assert set(fitted.x0_offsets) == set(data.zones) and blind.x0_offsets is None
    assert fitted.to_dict()["x0_offsets"]["Core"]["value"] == pytest.approx(off[-1])
    assert f"prior 0 +- 1: South {off[0]:+.2f}" in fitted.summary()
    assert "x(0) offsets" not in blind.summary() and blind.x0_offsets_line() == ""
    # the model keeps its 13 parameters (and c_IG per zone); the offsets are the fit's
    assert fitted.param_names == blind.param_names
    assert len(fitted.params) == len(fitted.stderr) == len(fitted.bounds) == len(names)
    assert set(fitted.priors) == set(names)
    sim = weekend_simulations(fitted.model, data, ["2015-04-18"], x0_offset=off)[0]
    assert rms_by_zone(sim["simulated"], sim["measured"], data.zones)["mean"] == \
        pytest.approx(fitted.train_rms["mean"], rel=1e-9)
    with pytest.raises(IdentificationError, match="needs a MAP fit"):
        identify(model, data, train=["2015-04-18"], x0_offset_sd=1.0)
    with pytest.raises(IdentificationError, match="must be > 0 K"):
        identify(model, data, train=["2015-04-18"], priors=priors, x0_offset_sd=0.0)


def test_weekend_occupancy_warning_names_the_zones_above_an_empty_office():
    """A daytime fit whose scales exceed an empty office's rise (1) says the weekends look
    occupied, naming those zones; scales at or below it, or none, say nothing."""
    from zonecast.estimator.pipeline import OCCUPIED_WEEKEND_SCALE, weekend_occupancy_warning

    assert OCCUPIED_WEEKEND_SCALE == 1.0
    assert weekend_occupancy_warning(None) is None
    assert weekend_occupancy_warning({"N": {"value": 0.4, "se": 0.1},
                                      "C": {"value": 1.0, "se": 0.2}}) is None
    msg = weekend_occupancy_warning({"N": {"value": 0.4, "se": 0.1},
                                     "C": {"value": 2.4, "se": 0.2}})
    assert msg.startswith("the weekends look occupied: zones C 2.4 fitted")
    assert "N 0.4" not in msg and "weekends without people" in msg
    assert "--weekend-gains metered" not in msg
    scales = {"C": {"value": 2.4, "se": 0.2}}
    assert "meters: --weekend-gains metered" in weekend_occupancy_warning(scales, metered=True)


def test_the_warning_believes_meters_that_show_empty_weekends():
    """Where the site's meters show empty weekends (their weekend rise below the auto
    threshold), a large fitted rise is heat the model lacks, not people: the warning says
    so, names the meters' ratio and `zonecast diagnose`, and does not offer the meters'
    option; at or above the threshold, or without meters, it is the occupancy warning."""
    from zonecast.estimator.pipeline import METERED_OCCUPIED_RATIO, weekend_occupancy_warning

    scales = {"N": {"value": 0.1, "se": 0.1}, "S": {"value": 2.41, "se": 0.2}}
    msg = weekend_occupancy_warning(scales, metered=True, metered_ratio=0.12)
    assert msg.startswith("zones S 2.4 fitted a weekend daytime rise")
    assert "meters show empty weekends" in msg and "0.12 of the working days'" in msg
    assert "not for people" in msg and "zonecast diagnose" in msg
    assert "look occupied" not in msg and "--weekend-gains metered" not in msg
    assert weekend_occupancy_warning({"S": {"value": 0.9, "se": 0.2}},
                                     metered_ratio=0.12) is None
    busy = weekend_occupancy_warning(scales, metered=True,
                                     metered_ratio=METERED_OCCUPIED_RATIO)
    assert busy.startswith("the weekends look occupied: zones S 2.4")
    assert "--weekend-gains metered" in busy
    assert weekend_occupancy_warning(scales, metered_ratio=None).startswith(
        "the weekends look occupied")


def test_the_warning_counts_a_weekend_days_own_scale():
    """With per-day deviations a zone's busiest day counts: a base scale of 0.8 with a
    Saturday 0.6 above it is a weekend with people."""
    from zonecast.estimator.pipeline import weekend_occupancy_warning

    base = {"N": {"value": 0.8, "se": 0.1}}
    assert weekend_occupancy_warning(base) is None
    days = {"N,2015-04-18": {"value": 0.6, "se": 0.2}, "N,2015-04-19": {"value": -0.5, "se": 0.2}}
    assert "zones N 1.4" in weekend_occupancy_warning(base, day_scale=days)
