"""The operator page ``/ui`` and the read-only resources it shows (history, health,
diagnosis), against a real service: uvicorn on a free port, SQLite holding 2.5 days of the
virtual building's telemetry (with sensors dropped on purpose), the runner caught up.

The browser test drives Debian's ``chromium`` headless with its ``chromedriver`` (Selenium):
it enters the token, waits for the charts, and reads the plotted series back from plotly.js
(``element.data``) to compare them with the stored readings, converted offline, and with
``/forecast``; the browser's console must stay free of errors. A wrong token must show an
error and no data. Skipped, with the reason, without chromium/chromedriver (``make ui-deps``).
A screenshot is written to ``$ZONECAST_UI_SCREENSHOT`` when that is set (docs/ui.png).
"""

from __future__ import annotations

import logging
import os
import shutil
import socket
import threading
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tests.service.helpers import wait_until as _wait

TOKEN = "ui-test-token-7f3a"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
DAY = 96
# 2.5 days stored (the 48-h window lies inside the data), ending on a full hour: with a
# forecast every 4 steps the last row issues one
N_ROWS = 2 * DAY + 49
WINDOW = 2 * DAY


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _diagnosis_file(path: Path, zones: list[str]) -> None:
    """A diagnosis.json as ``zonecast diagnose`` writes it (its own dataclass's to_dict),
    with one confident effect in the first zone and one unconfident one."""
    import json

    from zonecast.estimator.diagnose import Candidate

    a = Candidate("reheat", 18.0, [zones[0]], {zones[0]: 120.0}, score=0.31, confidence=0.999,
                  n_days=10, heldout_rms_before={zones[0]: 0.62, "mean": 0.40},
                  heldout_rms_after={zones[0]: 0.35, "mean": 0.33})
    b = Candidate("window_solar", None, [zones[1]], {zones[1]: 0.1}, score=0.01, confidence=0.6,
                  n_days=10, heldout_rms_before={"mean": 0.40},
                  heldout_rms_after={"mean": 0.40})
    path.write_text(json.dumps({"ranked_effects": [a.to_dict(), b.to_dict()], "where": {}}))


@pytest.fixture(scope="module")
def served(tmp_path_factory, vb, bundle, telemetry):
    """A running service (uvicorn in a thread) with 2.5 days stored and processed; yields
    (base URL, app, the stored rows as an SI frame)."""
    import uvicorn
    from zonecast.service.app import create_app
    from zonecast.service.settings import load_settings
    from zonecast.service.storage import open_storage

    tmp = tmp_path_factory.mktemp("ui")
    rows = telemetry.iloc[:N_ROWS].copy()
    frame = rows.set_index(pd.to_datetime(rows["time"], format="ISO8601", utc=True))
    frame = frame.drop(columns="time").astype(float)
    # holes the page must report: one sensor of the first zone for 6 rows of the window,
    # every sensor of the second zone for 3 rows, an airflow for 10 rows
    z0, z1 = bundle.zones[0], bundle.zones[1]
    sensors = bundle.site.points.zone_temperature
    frame.iloc[N_ROWS - 20:N_ROWS - 14, frame.columns.get_loc(sensors[z0][0].point)] = np.nan
    for s in sensors[z1]:
        frame.iloc[N_ROWS - 40:N_ROWS - 37, frame.columns.get_loc(s.point)] = np.nan
    box = next(iter(bundle.site.boxes.values())).airflow.point
    frame.iloc[N_ROWS - 60:N_ROWS - 50, frame.columns.get_loc(box)] = np.nan
    url = f"sqlite:///{tmp / 'zc.db'}"
    with open_storage(url) as store:
        long = frame.stack().dropna()
        store.put_readings("office6", [(p, t.to_pydatetime(), float(v))
                                       for (t, p), v in long.items()])
    _diagnosis_file(tmp / "diagnosis.json", bundle.zones)
    settings = load_settings(storage_url=url, api_tokens=[TOKEN], mqtt_enabled=False,
                             buildings={"office6": str(vb / "model.json")},
                             diagnoses={"office6": str(tmp / "diagnosis.json")},
                             runner={"poll_interval": 0.05, "forecast_every": 4,
                                     "publish": False})
    app = create_app(settings)
    port = _free_port()
    config = uvicorn.Config(app, host="127.0.0.1", port=port, log_level="info",
                            access_log=True, lifespan="on")
    server = uvicorn.Server(config)
    # every line the server logs (access log included): the token must never be in one
    lines = _Lines()
    for name in ("uvicorn.access", "uvicorn.error", "zonecast"):
        logging.getLogger(name).addHandler(lines)
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    _wait(lambda: server.started, 30, "uvicorn")
    last = frame.index[-1]
    runner = app.state.zc.runners["office6"]

    def caught_up():  # the last row processed and its forecast issued
        with runner.lock:
            return runner.forecast is not None and runner.forecast.issued == last

    _wait(caught_up, 60, "runner")
    app.state.log_lines = lines.lines
    yield f"http://127.0.0.1:{port}", app, frame
    server.should_exit = True
    thread.join(30)
    for name in ("uvicorn.access", "uvicorn.error", "zonecast"):
        logging.getLogger(name).removeHandler(lines)


class _Lines(logging.Handler):
    def __init__(self):
        super().__init__(logging.DEBUG)
        self.lines: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.lines.append(record.getMessage())


def _expected_y(bundle, frame: pd.DataFrame) -> np.ndarray:
    """Zone temperatures of ``frame`` by the offline (pandas) path of the estimator."""
    from zonecast.estimator.streaming import rows_from_frame

    return rows_from_frame(bundle, frame)[3]


def test_history_health_diagnosis_resources(served, bundle):
    import httpx
    from zonecast.estimator.streaming import OnlineEstimator, model_rows

    base, _, frame = served
    with httpx.Client(base_url=base, headers=AUTH, timeout=10) as c:
        hist = c.get("/api/v1/buildings/office6/history").json()
        health = c.get("/api/v1/buildings/office6/health").json()
        diag = c.get("/api/v1/buildings/office6/diagnosis").json()
        short = c.get("/api/v1/buildings/office6/history", params={"hours": 6}).json()
        assert c.get("/api/v1/buildings/office6/history",
                     params={"hours": 500}).status_code == 422
        for p in ("history", "health", "diagnosis"):
            r = c.get(f"/api/v1/buildings/office6/{p}", headers={"Authorization": "Bearer x"})
            assert r.status_code == 401, p
    win = frame.index[-WINDOW:]
    assert pd.DatetimeIndex(pd.to_datetime(hist["times"])).equals(win)
    assert len(short["times"]) == 24 and short["times"] == hist["times"][-24:]
    y = _expected_y(bundle, frame)[-WINDOW:]
    for j, z in enumerate(hist["zones"]):
        got = np.array([np.nan if v is None else v for v in z["measured"]])
        np.testing.assert_allclose(got, y[:, j], rtol=0, atol=1e-9, equal_nan=True)
    # the holes: zone 1 three rows without any sensor, zone 0 none (a sensor of it remains)
    miss = {z["zone"]: z["missing_steps"] for z in health["zones"]}
    assert miss == {z: int(np.isnan(y[:, j]).sum()) for j, z in enumerate(bundle.zones)}
    assert miss[bundle.zones[1]] == 3 and miss[bundle.zones[0]] == 0
    gaps = {g["point"]: g["missing"] for g in health["points_missing"]}
    assert gaps == {p: int(n) for p, n in frame.iloc[-WINDOW:].isna().sum().items() if n}
    assert health["window_steps"] == WINDOW
    assert health["last_reading"] == health["last_update"] == hist["times"][-1]
    # innovation RMS: the innovations of an offline estimator over the same rows
    d = model_rows(bundle, frame)
    est = OnlineEstimator(bundle)
    inn = np.array([est.advance(t, d.u[k], d.v[k], d.y[k], d.reheat[k]).innovation
                    for k, t in enumerate(d.times)])
    inn = inn[-WINDOW:]
    for j, z in enumerate(health["zones"]):
        ok = np.isfinite(inn[:, j])
        assert z["innovation_steps"] == ok.sum() == WINDOW - miss[z["zone"]]
        assert z["innovation_rms"] == pytest.approx(np.sqrt(np.mean(inn[ok, j] ** 2)), abs=1e-9)
        assert 0.01 < z["innovation_rms"] < 2.0
    assert diag["available"] and diag["file"] == "diagnosis.json"
    assert [e["effect"] for e in diag["effects"]] == ["reheat", "window_solar"]
    assert [e["confident"] for e in diag["effects"]] == [True, False]


def test_diagnosis_missing_or_unreadable_says_why(tmp_path):
    from zonecast.service.api.routes.diagnosis import read_diagnosis

    none = read_diagnosis("b", None)
    assert not none.available and "no diagnosis configured" in none.detail
    gone = read_diagnosis("b", tmp_path / "gone.json")
    assert not gone.available and gone.detail == "diagnosis file gone.json not found"
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    body = read_diagnosis("b", bad)
    assert not body.available and "unreadable" in body.detail
    assert str(tmp_path) not in body.detail and str(tmp_path) not in gone.detail


def test_ui_files_and_headers(served):
    import httpx

    base, _, _ = served
    with httpx.Client(base_url=base, timeout=10) as c:
        page = c.get("/ui")
        assert page.status_code == 200 and "text/html" in page.headers["content-type"]
        assert "script-src 'self'" in page.headers["content-security-policy"]
        assert 'src="/ui/plotly.min.js"' in page.text and 'src="/ui/ui.js"' in page.text
        js = c.get("/ui/plotly.min.js")
        assert js.status_code == 200 and "plotly.js v" in js.text[:200]
        assert c.get("/ui/ui.js").status_code == 200
        for bad in ("/ui/index.html", "/ui/..%2Fapp.py", "/ui/nope.js"):
            assert c.get(bad).status_code == 404, bad


# --------------------------------------------------------------------------- the browser
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMEDRIVER = shutil.which("chromedriver")


#: on the browser tests: skipped before the service fixture starts
needs_chromium = pytest.mark.skipif(
    CHROMIUM is None or CHROMEDRIVER is None,
    reason="needs Debian's chromium and chromium-driver on PATH (make ui-deps: "
           "apt-get install -y chromium chromium-driver)")


@pytest.fixture
def browser():
    webdriver = pytest.importorskip("selenium.webdriver", reason="selenium (dev extra)")
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--window-size=1500,1900", "--disable-extensions", "--no-first-run"):
        opts.add_argument(arg)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(executable_path=CHROMEDRIVER), options=opts)
    driver.set_page_load_timeout(30)
    yield driver
    driver.quit()


def _login(driver, base: str, token: str) -> str:
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    driver.get(base + "/ui")
    driver.execute_script("sessionStorage.clear()")
    driver.get(base + "/ui")
    WebDriverWait(driver, 20).until(
        lambda d: d.execute_script("return document.body.dataset.state") == "login")
    field = driver.find_element(By.ID, "token")
    field.send_keys(token)
    driver.find_element(By.CSS_SELECTOR, "#login button[type=submit]").click()
    WebDriverWait(driver, 30).until(
        lambda d: d.execute_script("return document.body.dataset.state") in ("ready", "error"))
    return driver.execute_script("return document.body.dataset.state")


def _local(times, tz: str) -> list[str]:
    return [t.strftime("%Y-%m-%d %H:%M:%S")
            for t in pd.DatetimeIndex(pd.to_datetime(times)).tz_convert(tz)]


@needs_chromium
def test_ui_plots_each_zone_in_headless_chromium(browser, served, bundle):
    import httpx
    from selenium.webdriver.common.by import By

    base, app, frame = served
    with httpx.Client(base_url=base, headers=AUTH, timeout=10) as c:
        fc = c.get("/api/v1/buildings/office6/forecast").json()
        gains = c.get("/api/v1/buildings/office6/internal-gains").json()
    tz = bundle.site.timezone
    assert _login(browser, base, TOKEN) == "ready"
    shot = os.environ.get("ZONECAST_UI_SCREENSHOT")
    if shot:
        browser.save_screenshot(shot)
    logs = browser.get_log("browser")
    errors = [e for e in logs if e["level"] in ("SEVERE", "ERROR")]
    assert errors == [], errors
    assert not browser.find_element(By.ID, "error").is_displayed()

    y = _expected_y(bundle, frame)[-WINDOW:]
    x_measured = _local(frame.index[-WINDOW:], tz)
    x_forecast = _local(fc["times"], tz)
    assert len(fc["times"]) == DAY
    for j, zone in enumerate(bundle.zones):
        traces = browser.execute_script(
            "const d = document.getElementById(arguments[0]); return d && d.data ? "
            "d.data.map(t => ({name: t.name, x: t.x, y: t.y})) : null;", f"chart-{j}")
        assert traces is not None, zone
        by = {t["name"]: t for t in traces}
        got = np.array([np.nan if v is None else v for v in by["measured"]["y"]])
        np.testing.assert_allclose(got, y[:, j], rtol=0, atol=1e-9, equal_nan=True)
        assert by["measured"]["x"] == x_measured
        zf = fc["zones"][j]
        assert zf["zone"] == zone
        np.testing.assert_allclose(by["forecast"]["y"], zf["mean"], rtol=0, atol=1e-9)
        np.testing.assert_allclose(by["interval lower"]["y"], zf["lower"], rtol=0, atol=1e-9)
        np.testing.assert_allclose(by["90 % interval"]["y"], zf["upper"], rtol=0, atol=1e-9)
        assert by["forecast"]["x"] == x_forecast
        assert by["f_IG online"]["y"] == [pytest.approx(gains["zones"][j]["online"], abs=1e-12)]
        card = browser.find_element(By.ID, f"chart-{j}").find_element(By.XPATH, "..").text
        assert zone in card and "Innovation RMS" in card and " K over " in card
    # the holes and the diagnosis are shown
    health = browser.find_element(By.ID, "health").text
    point = bundle.site.points.zone_temperature[bundle.zones[0]][0].point
    assert f"{point}: 6/{WINDOW}" in health
    cards = browser.find_elements(By.CSS_SELECTOR, "#zones .zone")
    assert f"3 of {WINDOW} steps" in cards[1].text
    assert "reheat" in browser.find_element(By.ID, "diagnosis").text
    assert "reheat (0.620 → 0.350 K)" in cards[0].text
    assert "no confident effect in this zone" in cards[1].text
    # the server logged the page's requests, never the token
    logged = app.state.log_lines
    assert any("/api/v1/buildings/office6/history?hours=48" in line for line in logged)
    assert any('"GET /ui HTTP' in line for line in logged)
    assert not any(TOKEN in line for line in logged)


@needs_chromium
def test_ui_wrong_token_shows_an_error_and_no_data(browser, served):
    from selenium.webdriver.common.by import By

    base, _, _ = served
    assert _login(browser, base, "not-the-token") == "error"
    err = browser.find_element(By.ID, "error")
    assert err.is_displayed() and "token was refused (401)" in err.text
    assert not browser.find_element(By.ID, "content").is_displayed()
    assert browser.find_elements(By.CSS_SELECTOR, "#zones .zone") == []
    assert browser.execute_script("return sessionStorage.getItem('zonecast-token')") is None
    assert browser.find_element(By.ID, "token").is_displayed()  # asked again
