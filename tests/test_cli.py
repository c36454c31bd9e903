import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tests.conftest import telemetry_frame, write_site
from zonecast.cli import app

runner = CliRunner()


def test_check_reports_a_valid_site(tmp_path, site_dict, telemetry_csv):
    df = telemetry_frame()
    df["Chiller kW"] = 3.0
    data = telemetry_csv(df)
    site = write_site(tmp_path, site_dict)
    res = runner.invoke(app, ["check", "--site", str(site), "--data", str(data)])
    assert res.exit_code == 0, res.output
    assert "2 zones, 3 rooms, 2 boxes" in res.output
    assert "8 steps" in res.output and "1 segment" in res.output
    assert "Chiller kW" in res.output


def test_check_fails_with_the_contract_message(tmp_path, site_dict, telemetry_csv):
    data = telemetry_csv(telemetry_frame().drop(columns=["OAT"]))
    site = write_site(tmp_path, site_dict)
    res = runner.invoke(app, ["check", "--site", str(site), "--data", str(data)])
    assert res.exit_code == 2
    assert "missing columns for points the site maps: OAT" in res.output


def test_testbed_rejects_bad_switches_and_dates(tmp_path):
    res = runner.invoke(app, ["testbed", "campaign", "--out", str(tmp_path), "--disable", "magic"])
    assert res.exit_code == 2 and "unknown effect" in res.output
    res = runner.invoke(app, ["testbed", "run", "--out", str(tmp_path), "--start", "2015-04-14"])
    assert res.exit_code == 2 and "must start on a Monday" in res.output
    res = runner.invoke(app, ["testbed", "run", "--out", str(tmp_path), "--start", "14/04/2015"])
    assert res.exit_code == 2 and "YYYY-MM-DD" in res.output


def test_model_on_nrels_five_zone_building(tmp_path):
    import json
    from pathlib import Path

    import numpy as np

    site = Path(__file__).resolve().parents[1] / "configs" / "sites" / "nrel" / "5ZoneAirCooled.site.yaml"
    out = tmp_path / "model.json"
    res = runner.invoke(app, ["model", "--site", str(site), "--out", str(out)])
    assert res.exit_code == 0, res.output
    summary = json.loads(out.read_text())
    assert summary["n_states"] == len(summary["state_labels"]) > 50
    assert summary["zones"] == {"South": ["SPACE1-1"], "East": ["SPACE2-1"], "North": ["SPACE3-1"],
                                "West": ["SPACE4-1"], "Core": ["SPACE5-1"]}
    assert summary["parameters"]["gamma_EW"]["unit"] == "W/(m2 K)"
    mats = np.load(out.with_suffix(".npz"))
    assert mats["A"].shape == (summary["n_states"],) * 2 and mats["C"].shape[0] == 5
    # its overhangs (Shading:Zone:Detailed) and return plenum are modelled, and said so
    assert "2 shaded windows" in res.output and "return air of 5 boxes" in res.output
    res = runner.invoke(app, ["model", "--site", str(site), "--out", str(out), "--params", "paper"])
    assert res.exit_code == 2 and "needs the paper's zones" in res.output


def test_forecast_offline_from_a_model_file(tmp_path):
    import datetime as dt
    import json

    import pandas as pd
    from zonecast.testbed.run import run_weeks

    run = run_weeks([dt.date(2015, 4, 13)], tmp_path / "week", seed=3)
    model = tmp_path / "model.json"
    model.write_text(json.dumps({"schema_version": 1, "site": "week/site.yaml", "parameters": {}}))
    csv = tmp_path / "fc.csv"
    args = ["forecast", "--model", str(model), "--data", str(run.out),
            "--at", "2015-04-15T00:00:00-07:00", "--horizon", "6h", "--out", str(csv)]
    res = runner.invoke(app, args)
    assert res.exit_code == 0, res.output
    table = pd.read_csv(csv)
    assert len(table) == 24 * 6 and set(table.zone) == {"NW", "NE", "W", "E", "S", "C"}
    assert (table.p05_degC < table.mean_degC).all() and (table.mean_degC < table.p95_degC).all()
    assert pd.Timestamp(table.time.iloc[0]) == pd.Timestamp("2015-04-15T00:15:00-07:00")
    res = runner.invoke(app, args[:6] + ["2015-04-15T00:00:00"])
    assert res.exit_code == 2 and "UTC offset" in res.output
    res = runner.invoke(app, args[:8] + ["48h"])
    assert res.exit_code == 2 and "between 15min and 24h" in res.output


def test_every_documented_command_exists():
    res = runner.invoke(app, ["--help"])
    assert res.exit_code == 0
    for cmd in ("testbed", "check", "model", "identify", "forecast", "reproduce", "demo", "serve",
                "replay", "mqtt-config"):
        assert cmd in res.output, cmd


def test_diagnose_fails_with_a_clear_message_on_a_missing_model(tmp_path):
    res = runner.invoke(app, ["diagnose", "--model", str(tmp_path / "none.json"), "--data",
                              str(tmp_path), "--out", str(tmp_path / "d")])
    assert res.exit_code == 2
    assert "none.json" in res.output


def test_identify_passes_the_internal_gains_option_to_the_model(tmp_path):
    """--internal-gains reaches ModelOptions: a wrong value fails with its message."""
    from pathlib import Path

    site = Path(__file__).resolve().parents[1] / "configs" / "sites" / "nrel" / "5ZoneAirCooled.site.yaml"
    res = runner.invoke(app, ["identify", "--site", str(site), "--data", str(tmp_path),
                              "--out", str(tmp_path / "m.json"), "--internal-gains", "walls"])
    assert res.exit_code == 2
    assert "internal_gains must be 'air' or 'idf'" in res.output


@pytest.mark.parametrize("command", ["identify", "reproduce"])
def test_window_angle_reaches_the_model_options(tmp_path, command):
    """--window-angle and --roof-exterior reach ModelOptions through both commands: a wrong
    value fails with the options' message."""
    from pathlib import Path

    site = Path(__file__).resolve().parents[1] / "configs" / "sites" / "nrel" / "5ZoneAirCooled.site.yaml"
    args = (["identify", "--site", str(site), "--data", str(tmp_path), "--out",
             str(tmp_path / "m.json")] if command == "identify" else
            ["reproduce", "--out", str(tmp_path / "r"), "--campaign", str(tmp_path)])
    if command == "reproduce":  # a campaign folder the job accepts without running one
        (tmp_path / "telemetry.csv").write_text("time\n")
        (tmp_path / "site.yaml").write_text(site.read_text().replace(
            "idf: 5ZoneAirCooled.idf", f"idf: {site.parent / '5ZoneAirCooled.idf'}"))
    for option, value, message in (
            ("--window-angle", "tinted", "window_angle must be 'none' or 'glass'"),
            ("--roof-exterior", "known",
             ("roof_exterior must be one of 'fitted', 'idf', 'absorptance', 'climate', "
              "'own', 'balance'")),
            ("--envelope-radiation", "star", "envelope_radiation must be 'none' or 'room'"),
            ("--solar-enclosure", "zone", "solar_enclosure must be 'room' or 'air_boundaries'")):
        res = runner.invoke(app, [*args, option, value])
        assert res.exit_code == 2, res.output
        assert message in res.output, option


def _stopped_at_identify(tmp_path, monkeypatch, command):
    """``command``'s arguments on NREL's 5-zone site with Pipeline.identify stopped at its
    call, and the dict that receives the call's keyword arguments."""
    from zonecast.estimator.pipeline import Pipeline

    seen = {}

    def stop(self, *args, **kwargs):
        seen.update(kwargs)
        raise ValueError("stopped after the call")

    monkeypatch.setattr(Pipeline, "identify", stop)
    monkeypatch.setattr(Pipeline, "data", lambda self, *a, **k: None)
    monkeypatch.setattr("zonecast.jobs.reproduce.week_split", lambda *a, **k: {"train": [0]})
    site = tmp_path / "site.yaml"
    args = (["identify", "--site", str(site), "--data", str(tmp_path), "--out",
             str(tmp_path / "m.json")] if command == "identify" else
            ["reproduce", "--out", str(tmp_path / "r"), "--campaign", str(tmp_path)])
    nrel = Path(__file__).resolve().parents[1] / "configs" / "sites" / "nrel"
    shutil.copy(nrel / "5ZoneAirCooled.site.yaml", site)
    shutil.copy(nrel / "5ZoneAirCooled.idf", tmp_path / "5ZoneAirCooled.idf")
    (tmp_path / "telemetry.csv").write_text("time\n")
    return args, seen


@pytest.mark.parametrize("command", ["identify", "reproduce"])
@pytest.mark.parametrize(("option", "value", "expected", "refused"),
                         [("--x0-profile-days", "2", 2, "0"),
                          ("--x0-offset-sd", "0.5", 0.5, "0")])
def test_x0_options_reach_the_pipeline(tmp_path, monkeypatch, command, option, value,
                                       expected, refused):
    """--x0-profile-days and --x0-offset-sd reach Pipeline.identify through both commands
    (which stop at the identification here); 0 is refused by each option's range."""
    args, seen = _stopped_at_identify(tmp_path, monkeypatch, command)
    res = runner.invoke(app, [*args, option, value])
    assert "stopped after the call" in res.output, res.output
    assert seen[option[2:].replace("-", "_")] == expected
    res = runner.invoke(app, [*args, option, refused])
    assert res.exit_code == 2 and option[2:] in res.output


@pytest.mark.parametrize("command", ["identify", "reproduce"])
def test_operating_films_reach_the_pipeline(tmp_path, monkeypatch, command):
    """--operating-films through both commands: 'natural' goes to Pipeline.identify, 'auto'
    identifies with the films everywhere ('none'; Pipeline.fit_operating_films decides
    after), and an unknown mode fails with a message naming the three."""
    args, seen = _stopped_at_identify(tmp_path, monkeypatch, command)
    for value, expected in (("natural", "natural"), ("auto", "none"), ("none", "none")):
        seen.clear()
        res = runner.invoke(app, [*args, "--operating-films", value])
        assert "stopped after the call" in res.output, res.output
        assert seen["operating_films"] == expected, value
    res = runner.invoke(app, [*args, "--operating-films", "always"])
    assert res.exit_code == 2
    assert "operating_films='always': use 'none' or 'natural' or 'auto'" in res.output


@pytest.mark.parametrize("command", ["identify", "reproduce"])
def test_constant_gains_reaches_the_identification(vb, tmp_path, command):
    """--constant-gains reaches Pipeline.identify through both commands: a wrong value
    fails with the identification's message before any fit."""
    args = (["identify", "--site", str(vb / "site.yaml"), "--data", str(vb), "--out",
             str(tmp_path / "m.json")] if command == "identify" else
            ["reproduce", "--out", str(tmp_path / "r"), "--campaign", str(vb), "--no-service",
             "--no-sensitivity"])
    res = runner.invoke(app, [*args, "--constant-gains", "known"])
    assert res.exit_code == 2, res.output
    assert "constant_gains='known': use 'fitted' or 'meters'" in res.output


def test_weather_error_is_checked_before_the_campaign_is_read(vb, tmp_path):
    """--weather-error names the testbed's irradiance-error form of the service check; a
    wrong one fails at once with the forms there are."""
    res = runner.invoke(app, ["reproduce", "--out", str(tmp_path / "r"), "--campaign", str(vb),
                              "--no-sensitivity", "--weather-error", "clouds"])
    assert res.exit_code == 2, res.output
    assert "weather_error must be one of cloud, factor, not 'clouds'" in res.output
