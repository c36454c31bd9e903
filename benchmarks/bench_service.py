"""Online step latency per building and forecast-endpoint latency under 50 concurrent clients.

1. **Step latency**: the online estimator of the virtual building (office6, 381 states,
   21 boxes, 6 zones) over two days of its telemetry: the filter + f_IG step alone, the
   day-ahead forecast alone (96 exact model steps; the interval widths are a table computed
   once per model), the storage read of one row, its conversion (units, zone averages,
   pvlib facade irradiance with the solar geometry cached per day), the checkpoint, and
   the runner step as the service does it: one new row stored, then one ``poll()``
   (watermark query, read, conversion, step, forecast every 4th step, checkpoint).
   References in the same run: one exact step propagator for a new airflow vector (the
   eigendecomposition the model caches per distinct u) and the general per-file
   conversion ``rows_from_frame`` applied to one row.
2. **Forecast endpoint**: ``zonecast serve`` in its own process (MQTT off, SQLite),
   50 concurrent clients each requesting the cached forecast; reference: ``/healthz``
   under the same load (the HTTP stack alone). With input forecasts on (the default
   since issue 15) a weather forecast is POSTed first (the testbed's, error growing with
   lead time) and the served forecast uses it with the learned HVAC inputs; on a version
   without the endpoint (``--no-weather`` or a 404) the step is skipped and said so. Closed-loop load comes from ``wrk`` (C,
   one thread) when it is on PATH, else from raw asyncio keep-alive connections in this
   process, which share the two cores with the server; paced load always from the
   asyncio clients. The output says which generator ran.

Usage::

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_service.py [--data DIR] [--requests 40]
        [--generator auto|wrk|python] [--seconds 10]
"""

from __future__ import annotations

import argparse
import asyncio
import datetime as dt
import os
import platform
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
import pandas as pd
from zonecast.estimator.constants import HORIZON, STEPS_PER_DAY
from zonecast.estimator.pipeline import Pipeline

TOKEN = "bench-token"


def _ms(values) -> str:
    a = np.asarray(values) * 1e3
    return f"median {np.median(a):.1f} ms, p90 {np.percentile(a, 90):.1f} ms, max {a.max():.1f} ms"


def virtual_building(data: Path | None, work: Path) -> Path:
    from zonecast.testbed.run import run_weeks

    if data is None:
        data = work / "vb"
        run_weeks([dt.date(2015, 4, 13)], data, seed=0)
    if not (data / "model.json").exists():
        Pipeline.from_site(data / "site.yaml").write_model_file(data / "model.json")
    return data


def bench_steps(data: Path, work: Path, days: int) -> dict:
    from zonecast.estimator.streaming import (
        STEP,
        OnlineEstimator,
        model_rows,
        rows_from_frame,
        telemetry_frame,
    )
    from zonecast.service.bodies import forecast_json
    from zonecast.service.runner import Runner
    from zonecast.service.settings import RunnerSettings
    from zonecast.service.storage import open_storage

    bundle = Pipeline.from_model_file(data / "model.json").bundle
    m = bundle.model
    frame = telemetry_frame(data, bundle).iloc[: STEPS_PER_DAY * (days + 1)]
    hist, live = frame.iloc[: STEPS_PER_DAY * days], frame.iloc[STEPS_PER_DAY * days:]
    rows = model_rows(bundle, hist)  # with the boxes' discharge-air rise when the site has it
    tt, u, v, y, rh = rows.times, rows.u, rows.v, rows.y, rows.reheat
    # reference: one exact propagator for a never-seen airflow vector
    ref = []
    for k in range(5):
        fresh = np.full(m.n_boxes, 0.123 + 0.01 * k)
        t0 = time.perf_counter()
        m.step_matrices(fresh)
        ref.append(time.perf_counter() - t0)
    est = OnlineEstimator(bundle)
    step, fc = [], []
    for k in range(len(tt)):
        t0 = time.perf_counter()
        est.advance(tt[k], u[k], v[k], y[k], rh[k])
        step.append(time.perf_counter() - t0)
        if k % 8 == 0:
            t0 = time.perf_counter()
            est.forecast()
            fc.append(time.perf_counter() - t0)
    distinct = len(np.unique(u, axis=0))
    # the runner: history stored and caught up, then one row at a time as in operation
    store = open_storage(f"sqlite:///{work / 'bench.db'}")
    units = bundle.site.point_units()

    def rows_of(f):
        return [(p, t, float(f.loc[t, p])) for t in f.index for p in units
                if np.isfinite(f.loc[t, p])]

    store.put_readings(bundle.building, rows_of(hist))
    runner = Runner(Pipeline.from_model_file(data / "model.json").bundle, store,
                    RunnerSettings(forecast_every=4))
    t0 = time.perf_counter()
    caught_up = runner.poll()
    catch_total = time.perf_counter() - t0
    catch = list(runner.latencies)
    served, served_fc, waiting, cpu_lean, cpu_fc = [], [], [], [], []
    for t in live.index:
        store.put_readings(bundle.building, rows_of(live.loc[[t]]))
        before = runner.forecast
        c0, t0 = time.thread_time(), time.perf_counter()
        n = runner.poll()
        dt_, cpu = time.perf_counter() - t0, time.thread_time() - c0
        if n == 0:
            waiting.append(dt_)
        elif n == 1:
            fresh = runner.forecast is not before
            (served_fc if fresh else served).append(dt_)
            (cpu_fc if fresh else cpu_lean).append(cpu)
    # parts of a served step, on the same data
    conv = runner.convert
    start = live.index[0]
    read, convert, general, ckpt, ckpt_store, ckpt_synced, body = [], [], [], [], [], [], []
    for k, t in enumerate(live.index[:48]):
        t0 = time.perf_counter()
        store.reading_bounds(bundle.building, t)
        times, values = store.readings_matrix(bundle.building, t, t + STEP, conv.points)
        read.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        conv.convert(times, values)
        convert.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        rows_from_frame(bundle, live.iloc[k:k + 1])
        general.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        blob = runner.est.to_bytes({"next_time": start.isoformat()})
        ckpt.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        store.save_checkpoint(bundle.building, start, blob, sync=False)
        ckpt_store.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        store.save_checkpoint(bundle.building, start, blob)
        ckpt_synced.append(time.perf_counter() - t0)
        runner.__dict__.pop("_body_cache", None)
        t0 = time.perf_counter()
        forecast_json(runner, HORIZON)
        body.append(time.perf_counter() - t0)
    store.close()
    return {"states": m.n, "boxes": m.n_boxes, "zones": m.n_zones, "steps": len(tt),
            "distinct_u": distinct, "propagator": ref, "step": step[1:], "forecast": fc,
            "read": read, "convert": convert, "general": general, "checkpoint": ckpt,
            "checkpoint_store": ckpt_store, "checkpoint_synced": ckpt_synced,
            "checkpoint_bytes": len(blob), "body": body,
            "catch_up": catch, "catch_steps": caught_up, "catch_total": catch_total,
            "served": served, "served_fc": served_fc, "waiting": waiting,
            "cpu": cpu_lean, "cpu_fc": cpu_fc}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


async def _client(port: int, path: str, n: int, period: float, lat: list[float]) -> None:
    """One keep-alive HTTP/1.1 connection sending ``n`` GETs (raw asyncio streams: an
    httpx client costs more CPU per request than the server, and client and server share
    the machine's two cores)."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    req = (f"GET {path} HTTP/1.1\r\nHost: 127.0.0.1\r\n"
           f"Authorization: Bearer {TOKEN}\r\n\r\n").encode()
    await asyncio.sleep(np.random.default_rng().uniform(0, period or 0.001))
    try:
        for _ in range(n):
            t0 = time.perf_counter()
            writer.write(req)
            await writer.drain()
            head = await reader.readuntil(b"\r\n\r\n")
            status = int(head.split(b" ", 2)[1])
            length = next(int(line.split(b":", 1)[1]) for line in head.split(b"\r\n")
                          if line.lower().startswith(b"content-length:"))
            await reader.readexactly(length)
            lat.append(time.perf_counter() - t0)
            if status != 200:
                raise RuntimeError(f"GET {path}: HTTP {status}")
            if period:
                await asyncio.sleep(max(0.0, period - (time.perf_counter() - t0)))
    finally:
        writer.close()


async def _load(port: int, path: str, clients: int, requests: int,
                period: float = 0.0) -> list[float]:
    """``clients`` concurrent clients, each sending ``requests`` requests back to back
    (``period`` 0: closed loop, saturation) or one every ``period`` seconds."""
    lat: list[float] = []
    await asyncio.gather(*(_client(port, path, requests, period, lat) for _ in range(clients)))
    return lat


def _wrk_seconds(text: str) -> float:
    for unit, scale in (("us", 1e-6), ("ms", 1e-3), ("s", 1.0), ("m", 60.0)):
        if text.endswith(unit) and text[: -len(unit)].replace(".", "", 1).isdigit():
            return float(text[: -len(unit)]) * scale
    raise ValueError(f"unexpected wrk latency {text!r}")


def _wrk(wrk: str, port: int, path: str, clients: int, seconds: float) -> dict:
    """Closed-loop load with wrk (C, epoll; one thread so that the server keeps a core):
    ``clients`` keep-alive connections sending back to back for ``seconds``."""
    out = subprocess.run([wrk, "-t1", f"-c{clients}", f"-d{seconds:g}s", "--latency",
                          "-H", f"Authorization: Bearer {TOKEN}",
                          f"http://127.0.0.1:{port}{path}"],
                         capture_output=True, text=True, check=True).stdout
    if "Non-2xx" in out or "Socket errors" in out:
        raise RuntimeError(f"wrk GET {path}: errors\n{out}")
    pct, total, rate = {}, None, None
    lines = out.splitlines()
    for i, line in enumerate(lines):
        f = line.split()
        if line.strip().startswith("Latency Distribution"):
            for row in lines[i + 1:i + 5]:
                q, val = row.split()
                pct[float(q.rstrip("%"))] = _wrk_seconds(val)
        elif "requests in" in line:
            total = int(f[0])
        elif line.startswith("Requests/sec:"):
            rate = float(f[1])
    return {"n": total, "rate": rate, "p50": pct[50.0], "p99": pct[99.0]}


def _summary(lat: list[float], rate: float) -> dict:
    a = np.asarray(lat)
    return {"n": len(a), "rate": rate, "p50": float(np.percentile(a, 50)),
            "p99": float(np.percentile(a, 99))}


def _weather_body(data: Path, tel: pd.DataFrame) -> dict | None:
    """The testbed's synthetic weather forecast issued at the first telemetry row."""
    try:
        from zonecast.estimator.telemetry import load_telemetry
        from zonecast.testbed.forecasts import weather_forecasts
    except ImportError:  # a version without weather forecasts
        return None
    from zonecast.estimator.site import load_site

    site = load_site(data / "site.yaml")
    frame = load_telemetry(data / "telemetry.csv", site).frame
    first = pd.Timestamp(tel.iloc[0]["time"]).tz_convert("UTC")
    bodies = weather_forecasts(site, frame.loc[:first + pd.Timedelta("2D")], every="1h",
                               hours=36)
    return bodies[0] if bodies else None


def bench_endpoint(data: Path, work: Path, clients: int, requests: int,
                   generator: str = "auto", seconds: float = 10.0,
                   weather: bool = True) -> tuple[dict, str]:
    import shutil

    import httpx

    port = _free_port()
    cfg = work / "service.yaml"
    cfg.write_text(f"storage_url: sqlite:///{work / 'serve.db'}\nmqtt_enabled: false\n"
                   f"api_tokens: [{TOKEN}]\nbuildings: {{office6: {data / 'model.json'}}}\n"
                   "runner: {poll_interval: 0.2, forecast_every: 4}\n")
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    exe = str(Path(sys.executable).parent / "zonecast")
    wrk = shutil.which("wrk") if generator in ("auto", "wrk") else None
    if generator == "wrk" and wrk is None:
        raise RuntimeError("--generator wrk: wrk is not on PATH (apt-get install wrk)")
    closed = "wrk (C, 1 thread)" if wrk else "Python asyncio clients in this process"
    proc = subprocess.Popen([exe, "serve", "--config", str(cfg), "--port", str(port),
                             "--log-level", "warning"], env=env)
    base = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 60
        while True:
            try:
                if httpx.get(base + "/readyz").status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            if time.monotonic() > deadline:
                raise RuntimeError("service did not become ready")
            time.sleep(0.2)
        tel = pd.read_csv(data / "telemetry.csv", dtype={"time": str})
        h = {"Authorization": f"Bearer {TOKEN}"}
        for i in range(9):
            row = tel.iloc[i]
            body = {"time": row["time"], "readings": {k: float(x) for k, x in row.items()
                                                      if k != "time" and pd.notna(x)}}
            httpx.post(base + "/api/v1/buildings/office6/telemetry", json=body, headers=h)
        wbody = _weather_body(data, tel) if weather else None
        status = "not sent"
        if wbody is not None:
            r = httpx.post(base + "/api/v1/buildings/office6/weather_forecast", json=wbody,
                           headers=h)
            status = f"POST weather_forecast -> {r.status_code}"
        print(f"   weather forecast: {status}", flush=True)
        while httpx.get(base + "/api/v1/buildings/office6/forecast", headers=h).status_code != 200:
            time.sleep(0.2)
        asyncio.run(_load(port, "/healthz", clients, 2))  # warm up
        out = {}
        fc_url = "/api/v1/buildings/office6/forecast?horizon=24h"
        for name, url in (("healthz", "/healthz"), ("forecast", fc_url)):
            if wrk:
                out[f"{name}, closed loop"] = _wrk(wrk, port, url, clients, seconds)
            else:
                t0 = time.perf_counter()
                lat = asyncio.run(_load(port, url, clients, requests))
                out[f"{name}, closed loop"] = _summary(lat, len(lat) / (time.perf_counter() - t0))
        for period in (1.0, 0.5):
            t0 = time.perf_counter()
            lat = asyncio.run(_load(port, fc_url, clients, max(10, requests // 4), period))
            out[f"forecast, each client every {period:g} s"] = _summary(
                lat, len(lat) / (time.perf_counter() - t0))
    finally:
        proc.terminate()
        proc.wait(10)
    return out, closed


def _report_steps(s: dict) -> None:
    print(f"\n1. online step, office6: {s['states']} states, {s['boxes']} boxes, "
          f"{s['zones']} zones; {s['steps']} steps, {s['distinct_u']} distinct airflow vectors")
    print(f"   reference, one exact propagator for a new u:   {_ms(s['propagator'])}")
    print(f"   reference, rows_from_frame for one row (general path, pandas): "
          f"{_ms(s['general'])}")
    print("   parts of a step:")
    print(f"     storage: watermark query + one row's readings: {_ms(s['read'])}")
    print(f"     one row's conversion (cached pvlib geometry):  {_ms(s['convert'])}")
    print(f"     filter + f_IG step:                          {_ms(s['step'])}")
    print(f"     checkpoint serialisation ({s['checkpoint_bytes'] / 1e3:.0f} kB):         "
          f"{_ms(s['checkpoint'])}")
    print(f"     checkpoint write (SQLite WAL, not synced per step):   "
          f"{_ms(s['checkpoint_store'])}")
    print(f"     reference, the same write synced (synchronous=FULL):  "
          f"{_ms(s['checkpoint_synced'])}")
    print(f"     day-ahead forecast (96 model steps):         {_ms(s['forecast'])}")
    print(f"     forecast JSON body (REST and MQTT, once per forecast): {_ms(s['body'])}")
    print("   runner step as served, one new row per poll (storage read, conversion, step, "
          "checkpoint):")
    print(f"     without forecast ({len(s['served'])} steps):  {_ms(s['served'])}")
    print(f"       CPU time of the thread:         {_ms(s['cpu'])}")
    print(f"     with forecast ({len(s['served_fc'])} steps):     {_ms(s['served_fc'])}")
    print(f"       CPU time of the thread:         {_ms(s['cpu_fc'])}")
    if s["waiting"]:
        print(f"     poll waiting for a row ({len(s['waiting'])}):  {_ms(s['waiting'])}")
    print(f"   catch-up of {s['catch_steps']} stored rows, per row without the storage read "
          f"(forecast every 4th): {_ms(s['catch_up'])}")
    lean = float(np.mean(s["cpu"]))  # CPU means: the disk sync is waiting, not work
    with_fc = float(np.mean(s["cpu_fc"]))
    hourly = (3 * lean + with_fc) / 4
    print(f"   by mean CPU time, one core keeps ~{900 / with_fc:.0f} buildings current with a "
          f"forecast every 15 min, ~{900 / hourly:.0f} with one per hour, ~{900 / lean:.0f} "
          "for state only")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, help="virtual-building folder (default: simulate one "
                                              "week)")
    ap.add_argument("--days", type=int, default=2)
    ap.add_argument("--clients", type=int, default=50)
    ap.add_argument("--requests", type=int, default=40, help="requests per client")
    ap.add_argument("--generator", choices=("auto", "wrk", "python"), default="auto",
                    help="closed-loop load generator (auto: wrk when on PATH)")
    ap.add_argument("--seconds", type=float, default=10.0, help="wrk run length per endpoint")
    ap.add_argument("--skip-steps", action="store_true", help="only the endpoint benchmark")
    ap.add_argument("--skip-endpoint", action="store_true", help="only the step benchmark")
    ap.add_argument("--no-weather", action="store_true",
                    help="do not POST a weather forecast before the endpoint benchmark")
    args = ap.parse_args()
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python "
          f"{platform.python_version()}, OPENBLAS_NUM_THREADS={os.environ['OPENBLAS_NUM_THREADS']}")
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        data = virtual_building(args.data, work)
        if not args.skip_steps:
            _report_steps(bench_steps(data, work, args.days))
        if args.skip_endpoint:
            return
        e, closed = bench_endpoint(data, work, args.clients, args.requests, args.generator,
                                   args.seconds, weather=not args.no_weather)
        print(f"\n2. REST under {args.clients} concurrent keep-alive clients (server: one "
              "uvicorn process, on the same 2 cores as the load)")
        print(f"   closed-loop load generator: {closed}; paced load: Python asyncio clients")
        for name, r in e.items():
            print(f"   {name:34s} {r['n']:6d} requests, {r['rate']:6.0f} req/s: p50 "
                  f"{r['p50'] * 1e3:6.1f} ms, p99 {r['p99'] * 1e3:6.1f} ms")
        print("   target: forecast p99 <= 50 ms")


if __name__ == "__main__":
    main()
