"""Benchmark and measurements of the RC model on the virtual building (issue 3).

In one run:
1. EnergyPlus simulates the 11-week campaign (the reference, timed by the testbed);
2. the RC model is read from the campaign's IDF, built and discretised (timed);
3. the model simulates the same 11 weeks from the recorded u and v (exact stepping,
   median of 3), side by side with EnergyPlus's time;
4. discretisation error on a week of virtual-building inputs: exact stepping against
   dense per-step exponentials ("eig"), against a stiff ODE solver (Radau, one day) and
   the paper's fixed-matrix form against exact;
5. the open-loop gap before any fitting: Table 1's values (and the physical starting
   values), f_IG = 0, x(0) from a Kalman filter run over the week's first day, then open
   loop for the remaining 6 days; per-zone RMS against the measured zone temperatures.

Usage: python benchmarks/bench_model.py [--campaign DIR]   (DIR reused if it holds a run)
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices: threads only contend

import argparse
import platform
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp
from zonecast.estimator.evaluate import rms_by_zone
from zonecast.estimator.kalman import (
    default_initial_covariance,
    default_measurement_noise,
    default_process_noise,
    initial_state_from_measurement,
    run_filter,
)
from zonecast.estimator.pipeline import Pipeline
from zonecast.estimator.rc.parameters import ParameterSet


def campaign(dir_: Path | None):
    from zonecast.testbed.run import run_campaign
    if dir_ is not None and (dir_ / "run.json").is_file():
        import json
        print(f"reusing {dir_}: EnergyPlus time is from that earlier run, not this one")
        return dir_, json.loads((dir_ / "run.json").read_text())["timings"]["energyplus_s"]
    out = dir_ or Path(tempfile.mkdtemp()) / "campaign"
    eps = []
    for i in range(3):  # EnergyPlus's time varies from run to run: median of 3
        res = run_campaign(out, seed=0)
        eps.append(res.timings["energyplus_s"])
        print(f"EnergyPlus campaign run {i + 1}: {eps[-1]:.2f} s")
    return out, sorted(eps)[1]


def kalman_x0(model, d, k0, k1):
    """Filter over rows [k0, k1) and return the filtered state at row k1."""
    air = model.structure.air_states()
    y = d.y[k0:k1 + 1]
    x0 = initial_state_from_measurement(y[0], model.state_zones())
    P0 = default_initial_covariance(model.n, air)
    gains = model.params.c_ig

    def step(k):
        phi, gv, gi = model.step_matrices(d.u[k0 + k])
        return phi, gv @ d.v[k0 + k] + gi @ gains

    res = run_filter(x0, P0, step, y, model.C, default_process_noise(model.n, air),
                     default_measurement_noise(model.n_zones), store_covariance="none")
    return res.x[-1]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--campaign", type=Path, default=None)
    args = ap.parse_args()
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
          f"numpy {np.__version__}")
    out, t_ep = campaign(args.campaign)
    pipe = Pipeline.from_site(out / "site.yaml")
    site = pipe.site
    tel = pipe.telemetry(out / "telemetry.csv")
    t0 = time.perf_counter()
    pipe.building()
    t1 = time.perf_counter()
    model = pipe.model()
    x0 = np.full(model.n, 20.0)
    d = pipe.data(tel)
    model.simulate(x0, d.u[:2], d.v[:2])          # compile the kernel (cached on disk after)
    t2 = time.perf_counter()
    print(f"states: {model.n} {model.structure.state_counts()}")
    print(f"read IDF {t1 - t0:.2f} s; build + discretise (incl. kernel load) {t2 - t1:.3f} s")
    times = []
    for _ in range(3):
        t = time.perf_counter()
        model.simulate(x0, d.u, d.v)
        times.append(time.perf_counter() - t)
    t_model = sorted(times)[1]
    print(f"11 weeks ({len(d)} steps): model {t_model:.3f} s (median of 3), EnergyPlus "
          f"{t_ep:.2f} s (median of 3) in the same run -> model {t_ep / t_model:.1f}x faster (target >= 20x)")

    # discretisation error on the spring excitation week
    week = [s for s in d.segments if d.excitation[s[0]:s[1]].any()][1]
    k0, k1 = week
    u, v = d.u[k0:k1], d.v[k0:k1]
    xs = kalman_x0(model, d, k0, k0 + 96)
    t = time.perf_counter()
    eig = model.simulate(xs, u, v, method="eig")
    t_eig = time.perf_counter() - t
    exact = model.simulate(xs, u, v)
    fixed = model.simulate(xs, u, v, method="bilinear")
    print(f"week of virtual-building inputs: exact vs dense per-step exponentials max "
          f"{np.abs(exact.y - eig.y).max():.1e} C (eig method took {t_eig:.2f} s)")
    err = np.abs(fixed.y - exact.y)
    print(f"paper's fixed-matrix form vs exact: max {err.max():.2f} C, RMS "
          f"{np.sqrt((err ** 2).mean()):.3f} C")
    # stiff reference over one day
    A = model.A
    gains = model.params.c_ig
    x = exact.x[0]
    ref = [x]
    for k in range(96):
        Ak = model.system_matrix(u[k])
        bk = model.input_matrix(u[k]) @ v[k] + model.B_ig @ gains
        sol = solve_ivp(lambda _t, z, Ak=Ak, bk=bk: Ak @ z + bk, (0, 900.0), x, method="Radau",
                        rtol=1e-10, atol=1e-10, jac=Ak)
        x = sol.y[:, -1]
        ref.append(x)
    ref = np.array(ref) @ model.C.T
    print(f"exact vs Radau (rtol 1e-10), one day: max {np.abs(exact.y[:97] - ref).max():.1e} C")
    del A

    # open-loop gap, per week: KF over day 1, open loop days 2-7, f_IG = 0
    for label, params in (("paper Table 1", ParameterSet.paper_table1()),
                          ("physical start values", ParameterSet(list(site.zones)))):
        if list(params.zones) != list(site.zones):  # same zone names, site order
            params = ParameterSet(list(site.zones), {n: params[n] for n in params.param_names})
        m = model.with_params(params)
        preds, meas = [], []
        for a, b in d.segments:
            xk = kalman_x0(m, d, a, a + 96)
            sim = m.simulate(xk, d.u[a + 96:b], d.v[a + 96:b])
            preds.append(sim.y[:-1])
            meas.append(d.y[a + 96:b])
        r = rms_by_zone(np.vstack(preds), np.vstack(meas), d.zones)
        print(f"open-loop gap, {label}, f_IG = 0, 11 weeks x 6 days: "
              + ", ".join(f"{z} {r[z]:.2f}" for z in d.zones) + f"; mean {r['mean']:.2f} C")


if __name__ == "__main__":
    main()
