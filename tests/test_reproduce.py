"""results.json validates against its schema; the report shows the paper's numbers beside ours."""

import json

import numpy as np
import pytest
from pydantic import ValidationError

from zonecast.jobs.reproduce import PAPER, Results, plot_horizon, plot_week, write_report

ZONES = ["NW", "NE", "W", "E", "S", "C"]


def rms(x):
    return {**{z: x for z in ZONES}, "mean": x}


def results(**over):
    data = {"seed": 0,
            "parameters": {"gamma_EW": {"value": 10.5, "unit": "W/(m2 K)", "stderr": 0.4}},
            "table2": {"training": rms(0.3), "validation": rms(0.4)},
            "table3": {"fixed": rms(0.5), "online_paper": rms(0.3), "dayahead": rms(0.45)},
            "horizon_rms": {"fixed": {z: [0.1, 0.2, 0.3] for z in [*ZONES, "mean"]}},
            "gains_truth": {"NW": {"total": {"r": 0.8, "scale": 0.9}}},
            "coverage_90": {"fixed": 0.88},
            "split": {"identification": {"train": ["2015-04-18"], "validation": ["2014-10-11"]}}}
    data.update(over)
    return Results.model_validate(data)


def test_schema_accepts_a_complete_result_and_round_trips():
    from zonecast.estimator.artifact import model_options_dict
    from zonecast.estimator.rc.network import ModelOptions
    r = results(model_options=model_options_dict(ModelOptions()),
                table2_window_solar_air={"training": {"mean": 0.44}, "validation": None})
    again = Results.model_validate(json.loads(r.model_dump_json()))
    assert again == r
    assert "table3" in Results.model_json_schema()["required"]


@pytest.mark.parametrize("missing", ["table3", "parameters", "horizon_rms", "seed", "split"])
def test_schema_rejects_missing_parts(missing):
    data = json.loads(results().model_dump_json())
    data.pop(missing)
    with pytest.raises(ValidationError, match=missing):
        Results.model_validate(data)


def test_report_puts_the_papers_numbers_beside_ours(tmp_path):
    r = results()
    plot_horizon(r.horizon_rms, ZONES, tmp_path / "fig3.png")
    text = write_report(r, tmp_path, ["fig3.png"], ZONES).read_text()
    assert "| fixed | 0.500 |" in text
    assert f"| paper fixed | {PAPER['table3']['fixed']['NW']:.2f} |" in text
    assert "**0.300**" in text and "0.333" in text and "![fig3.png](fig3.png)" in text
    assert (tmp_path / "fig3.png").stat().st_size > 1000


def test_week_figure_draws_measured_and_predictions_with_gaps(tmp_path):
    import numpy as np
    import pandas as pd

    times = pd.date_range("2015-01-12", periods=96 * 7, freq="15min", tz="America/Los_Angeles")
    base = 20 + np.sin(np.arange(len(times)) / 15)
    gap = [None] * 96 + list(base[96:] + 0.2)          # no forecast on the first day
    week = {"start": "2015-01-12", "times": [t.isoformat() for t in times],
            "measured": {z: base.tolist() for z in ZONES},
            "fixed": {z: gap for z in ZONES}, "dayahead": {z: gap for z in ZONES}}
    path = tmp_path / "fig4.png"
    plot_week(week, ZONES, ["fixed", "dayahead"], "Fig. 4", path)
    assert path.stat().st_size > 10_000
    with pytest.raises(KeyError):
        plot_week(week, ZONES, ["online_paper"], "Fig. 5", tmp_path / "fig5.png")


def test_weekend_figure_has_a_panel_per_zone_and_weekend(tmp_path):
    from zonecast.jobs.reproduce import plot_weekends
    rng = np.random.default_rng(0)
    sims = [{"saturday": d, "measured": 21 + rng.normal(0, 0.2, (192, len(ZONES))),
             "simulated": np.full((192, len(ZONES)), 21.0)} for d in ("2015-04-18", "2014-10-11")]
    path = tmp_path / "fig1.png"
    plot_weekends(sims, {"2015-04-18": "training", "2014-10-11": "validation"}, ZONES, path)
    assert path.stat().st_size > 5000


def test_report_names_parameters_at_a_bound_and_identifiability(tmp_path):
    r = results(parameters={
        "gamma_EW": {"value": 10.5, "unit": "W/(m2 K)", "stderr": 0.4, "bounds": [1.0, 100.0]},
        "gamma_ceil": {"value": 0.001, "unit": "W/(m2 K)", "stderr": 2.0,
                       "bounds": [0.001, 50.0], "at_bound": True}},
        identification={"jacobian_rank": 11, "jacobian_condition": 3.2e5,
                        "strongly_correlated": [["gamma_EW", "U_win", -0.93]]})
    text = write_report(r, tmp_path, [], ZONES).read_text()
    assert "| gamma_ceil | 0.001 | 2 | W/(m2 K) | [0.001, 50] | **at a bound** |" in text
    assert "Parameters at a bound (the data do not determine them; the bound does): gamma_ceil." \
        in text
    assert "Jacobian rank 11 of 2, condition number 3.2e+05" in text
    assert "gamma_EW/U_win -0.93" in text


@pytest.mark.timeout(600)
def test_reproduce_end_to_end_without_the_service_check(tmp_path, paper_campaign):
    """The whole job on the default campaign (real EnergyPlus, 11 weeks; the run's shared
    ``run_campaign(seed=0)``, which the job would run itself without ``campaign``) with
    ``service=False``: Tables 2 and 3 without the service rows, the report saying so, a
    model file the service can load, and office6's Table 2 within its must (0.208 / 0.203;
    160-210 s on a 2-core machine beside the rest of the suite, 2026-12-07)."""
    from zonecast.estimator.artifact import load_model_file

    from zonecast.jobs import reproduce

    res = reproduce.run(tmp_path / "report", campaign=paper_campaign, seed=0,
                        sensitivity=False, service=False)
    assert not [k for k in res.table3 if k.startswith("service")]
    assert {"fixed", "dayahead", "online_paper"} <= set(res.table3)
    assert "service_check" not in res.timings_s
    report = (tmp_path / "report" / "report.md").read_text()
    assert "was left out (`zonecast reproduce --no-service`)" in report
    again = Results.model_validate_json((tmp_path / "report" / "results.json").read_text())
    assert again.table3 == res.table3
    assert load_model_file(tmp_path / "report" / "model.json").model.params is not None
    assert res.table2["training"]["mean"] <= 0.208
    assert res.table2["validation"]["mean"] <= 0.203
    assert res.table3["fixed"]["mean"] <= 0.318
    # office6 has meters but nobody at weekends: the default picks the daytime rise
    ident = res.identification
    assert ident["weekend_gains_asked"] == "auto" and ident["weekend_gains"] == "daytime"
    assert 0.0 < ident["weekend_metered_ratio"] < 0.15
    assert "the weekends are not occupied and the weekend daytime rise" in report
    # and its x(0) filter knows the working days' metered lights and plugs (x0_meters auto)
    assert ident["x0_gains"] is True and ident["x0_gains_source"] == "meters"
    assert "x(0) filter: the working day before each weekend with each zone's metered" in report


def test_report_says_which_weekend_gains_the_meters_chose(tmp_path):
    """With --weekend-gains auto the report gives the meters' ratio and the mode it chose."""
    scale = {z: {"value": 0.0, "se": 0.1} for z in ZONES}
    text = write_report(results(identification={
        "weekend_gains_asked": "auto", "weekend_gains": "metered",
        "weekend_metered_ratio": 0.31, "gain_scale": scale}), tmp_path, [], ZONES).read_text()
    assert "weekend daytime rise is 0.31 of the working days' (threshold 0.15)" in text
    assert "the weekends are occupied and the metered rise is known gains" in text
    assert "metered lights and plug loads above its weekend night base" in text
    plain = write_report(results(identification={"weekend_gains": "daytime",
                                                  "gain_scale": scale}),
                         tmp_path, [], ZONES).read_text()
    assert "chosen from the site's meters" not in plain


def test_report_states_the_x0_offsets_when_fitted(tmp_path):
    """With --x0-offset-sd the report says every weekend starts at the filter's state plus
    the fitted offsets, with their prior; without, it says nothing of them."""
    offsets = {z: {"value": 0.8, "se": 0.1, "prior_sd": 0.5} for z in ZONES}
    text = write_report(results(identification={"x0_offsets": offsets}), tmp_path, [],
                        ZONES).read_text()
    assert "prior 0 ± 0.5 K" in text and "NW +0.80 ± 0.10 K" in text
    plain = write_report(results(identification={"x0_offsets": None}), tmp_path, [],
                         ZONES).read_text()
    assert "offset" not in plain


def test_report_says_why_the_operating_films_were_or_were_not_taken(tmp_path):
    """--operating-films auto: the report gives the reheat-leak test that decided, with the
    factors when it took them and the threshold when it did not."""
    factors = {"gamma_floor": 1 / 1.30, "gamma_IW": 1 / 1.14, "gamma_ceil": 1 / 1.04}
    took = write_report(results(identification={
        "operating_films": factors,
        "operating_films_test": {"k_mean": 0.18, "stderr": 0.002, "min_t": 3.0,
                                 "applied": True}}), tmp_path, [], ZONES).read_text()
    assert "the identified ones × gamma_floor 0.769, gamma_IW 0.877, gamma_ceil 0.962" in took
    assert "mean reheat leak at the identified films k +0.180 ± 0.002" in took
    kept = write_report(results(identification={
        "operating_films": None,
        "operating_films_test": {"k_mean": -0.108, "stderr": 0.011, "min_t": 3.0,
                                 "applied": False}}), tmp_path, [], ZONES).read_text()
    assert "Inside films in regular operation: the identified ones" in kept
    assert "k -0.108 ± 0.011, below 3 standard errors" in kept
    plain = write_report(results(identification={}), tmp_path, [], ZONES).read_text()
    assert "Inside films in regular operation" not in plain


def test_service_check_forecasts_are_written_again_only_when_the_testbed_wrote_others(
        vb, tmp_path):
    """The campaign's weather forecasts: written with the asked error form when absent, used
    as they are when they came from elsewhere (no error model recorded), written again
    when the testbed wrote them with another form or seed; the forms are the testbed's."""
    from zonecast.testbed.forecasts import IRRADIANCE_ERRORS, error_model

    from zonecast.jobs.reproduce import WEATHER_ERRORS, _weather_forecasts

    assert set(WEATHER_ERRORS) == set(IRRADIANCE_ERRORS)
    assert WEATHER_ERRORS[0] == error_model()["irradiance_error"]
    for name in ("site.yaml", "telemetry.csv"):
        (tmp_path / name).symlink_to(vb / name)
    said = []
    cloud = _weather_forecasts(tmp_path, 1, "cloud", said.append)
    doc = json.loads((tmp_path / "weather_forecasts.json").read_text())
    assert doc["error_model"] == error_model() and doc["seed"] == 1 and not said
    factor = _weather_forecasts(tmp_path, 1, "factor", said.append)
    assert json.loads((tmp_path / "weather_forecasts-factor.json").read_text())[
        "error_model"]["irradiance_error"] == "factor"
    assert len(factor) == len(cloud) and not said
    assert any(not np.array_equal(a.ghi, b.ghi) for a, b in zip(cloud, factor))
    # another seed: written again, and said so
    again = _weather_forecasts(tmp_path, 2, "cloud", said.append)
    assert said and "written with another seed or error model" in said[0]
    assert json.loads((tmp_path / "weather_forecasts.json").read_text())["seed"] == 2
    assert any(not np.array_equal(a.ghi, b.ghi) for a, b in zip(cloud, again))
    # forecasts from elsewhere (no error model recorded) are used as they are
    doc = json.loads((tmp_path / "weather_forecasts.json").read_text())
    del doc["error_model"]
    doc["forecasts"] = doc["forecasts"][:3]
    (tmp_path / "weather_forecasts.json").write_text(json.dumps(doc))
    assert len(_weather_forecasts(tmp_path, 1, "cloud")) == 3
