"""Online step latency per building and forecast-endpoint latency under 50 concurrent clients.

1. **Step latency**: the online estimator of the virtual building (office6, 381 states,
   21 boxes, 6 zones) over two days of its telemetry: the filter + f_IG step alone, the
   day-ahead forecast alone (96 exact model steps; the interval widths are a table computed
   once per model), one row's telemetry conversion (units, zone averages, pvlib facade
   irradiance), the checkpoint, and the whole runner step as the service does it (storage read, step, forecast, checkpoint).
   Reference in the same run: one exact step propagator for a new airflow vector (the
   eigendecomposition the model caches per distinct u).
2. **Forecast endpoint**: ``zonecast serve`` in its own process (MQTT off, SQLite),
   50 concurrent clients each requesting the cached forecast; reference: ``/healthz``
   under the same load (the HTTP stack alone). The clients are raw asyncio
   keep-alive connections in this process (an httpx client would cost more CPU per
   request than the server on the same two cores).

Usage::

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_service.py [--data DIR] [--requests 40]
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

TOKEN = "bench-token"


def _ms(values) -> str:
    a = np.asarray(values) * 1e3
    return f"median {np.median(a):.1f} ms, p90 {np.percentile(a, 90):.1f} ms, max {a.max():.1f} ms"


def virtual_building(data: Path | None, work: Path) -> Path:
    from zonecast.service.modelfile import write_model_file
    from zonecast.testbed.run import run_weeks

    if data is None:
        data = work / "vb"
        run_weeks([dt.date(2015, 4, 13)], data, seed=0)
    if not (data / "model.json").exists():
        write_model_file(data / "model.json", data / "site.yaml")
    return data


def bench_steps(data: Path, work: Path, days: int) -> dict:
    from zonecast.service.modelfile import load_model_file
    from zonecast.service.offline import telemetry_frame
    from zonecast.service.online import OnlineEstimator, rows_from_frame
    from zonecast.service.runner import Runner
    from zonecast.service.settings import RunnerSettings
    from zonecast.service.storage import open_storage

    bundle = load_model_file(data / "model.json")
    m = bundle.model
    frame = telemetry_frame(data, bundle).iloc[: 96 * days]
    tt, u, v, y = rows_from_frame(bundle, frame)
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
        est.advance(tt[k], u[k], v[k], y[k])
        step.append(time.perf_counter() - t0)
        if k % 8 == 0:
            t0 = time.perf_counter()
            est.forecast()
            fc.append(time.perf_counter() - t0)
    distinct = len(np.unique(u, axis=0))
    conv, ckpt = [], []
    for k in range(0, len(frame), 8):
        t0 = time.perf_counter()
        rows_from_frame(bundle, frame.iloc[k:k + 1])
        conv.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        blob = est.to_bytes()
        ckpt.append(time.perf_counter() - t0)
    # the whole runner step as served: storage read, step, forecast, checkpoint
    store = open_storage(f"sqlite:///{work / 'bench.db'}")
    units = bundle.site.point_units()
    rows = [(p, t, float(frame.loc[t, p])) for t in frame.index for p in units
            if np.isfinite(frame.loc[t, p])]
    store.put_readings(bundle.building, rows)
    runner = Runner(load_model_file(data / "model.json"), store,
                    RunnerSettings(forecast_every=1))
    t0 = time.perf_counter()
    n = runner.poll()
    total = time.perf_counter() - t0
    store.close()
    return {"states": m.n, "boxes": m.n_boxes, "zones": m.n_zones, "steps": len(tt),
            "distinct_u": distinct, "propagator": ref, "step": step[1:], "forecast": fc,
            "convert": conv, "checkpoint": ckpt, "checkpoint_bytes": len(blob),
            "runner_steps": n, "runner_total": total, "runner": list(runner.latencies)}


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


def bench_endpoint(data: Path, work: Path, clients: int, requests: int) -> dict:
    import httpx

    port = _free_port()
    cfg = work / "service.yaml"
    cfg.write_text(f"storage_url: sqlite:///{work / 'serve.db'}\nmqtt_enabled: false\n"
                   f"api_tokens: [{TOKEN}]\nbuildings: {{office6: {data / 'model.json'}}}\n"
                   "runner: {poll_interval: 0.2, forecast_every: 4}\n")
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    exe = str(Path(sys.executable).parent / "zonecast")
    proc = subprocess.Popen([exe, "serve", "--config", str(cfg),
                             "--port", str(port), "--log-level", "warning"], env=env)
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
        while httpx.get(base + "/api/v1/buildings/office6/forecast", headers=h).status_code != 200:
            time.sleep(0.2)
        asyncio.run(_load(port, "/healthz", clients, 2))  # warm up
        out = {}
        fc_url = "/api/v1/buildings/office6/forecast?horizon=24h"
        for name, url in (("healthz", "/healthz"), ("forecast", fc_url)):
            t0 = time.perf_counter()
            lat = asyncio.run(_load(port, url, clients, requests))
            out[f"{name}, closed loop"] = (lat, len(lat) / (time.perf_counter() - t0))
        for period in (1.0, 0.5):
            t0 = time.perf_counter()
            lat = asyncio.run(_load(port, fc_url, clients, max(10, requests // 4), period))
            out[f"forecast, each client every {period:g} s"] = (
                lat, len(lat) / (time.perf_counter() - t0))
    finally:
        proc.terminate()
        proc.wait(10)
    return out


def _report_steps(s: dict) -> None:
    print(f"\n1. online step, office6: {s['states']} states, {s['boxes']} boxes, "
          f"{s['zones']} zones; {s['steps']} steps, {s['distinct_u']} distinct airflow vectors")
    print(f"   reference, one exact propagator for a new u: {_ms(s['propagator'])}")
    print(f"   filter + f_IG step:                          {_ms(s['step'])}")
    print(f"   day-ahead forecast (96 model steps):         {_ms(s['forecast'])}")
    print(f"   one row's telemetry conversion (pvlib, pandas): {_ms(s['convert'])}")
    print(f"   checkpoint serialisation ({s['checkpoint_bytes'] / 1e3:.0f} kB):     "
          f"{_ms(s['checkpoint'])}")
    print(f"   runner step as served (read, step, forecast every step, checkpoint): "
          f"{_ms(s['runner'])}")
    per = float(np.mean(s["runner"]))  # means: propagator cache misses count
    lean = float(np.mean(s["step"]))
    hourly = lean + float(np.mean(s["forecast"])) / 4
    print(f"   one core keeps ~{900 / per:.0f} buildings current with a forecast every 15 min, "
          f"~{900 / hourly:.0f} with one forecast per hour, ~{900 / lean:.0f} for state only")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, help="virtual-building folder (default: simulate one "
                                              "week)")
    ap.add_argument("--days", type=int, default=2)
    ap.add_argument("--clients", type=int, default=50)
    ap.add_argument("--requests", type=int, default=40, help="requests per client")
    ap.add_argument("--skip-steps", action="store_true", help="only the endpoint benchmark")
    ap.add_argument("--skip-endpoint", action="store_true", help="only the step benchmark")
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
        e = bench_endpoint(data, work, args.clients, args.requests)
        print(f"\n2. REST under {args.clients} concurrent clients (server: one uvicorn process; "
              "clients: raw asyncio connections in this process, on the same 2 cores)")
        for name, (lat, rate) in e.items():
            a = np.asarray(lat) * 1e3
            print(f"   {name:34s} {len(a):5d} requests, {rate:6.0f} req/s: p50 "
                  f"{np.percentile(a, 50):6.1f} ms, p99 {np.percentile(a, 99):6.1f} ms")
        print("   target: forecast p99 <= 50 ms")


if __name__ == "__main__":
    main()
