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
