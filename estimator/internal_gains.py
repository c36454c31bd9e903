"""Time-varying internal gains from data, paper section 4-B (sec:fixed_ig) and section 5.

For each step the model is stepped with f_IG(k-1) = 0 (paper Eq:xnoig_ynoig); the
measured zone temperatures then give f_IG(k-1) by ordinary least squares from
(C B_IG) f_IG(k-1) = ȳ(k) - ỹ(k) (paper Eq:ig(k-1)), and the state is carried on as
x(k) = x̃(k) + B_IG f_IG(k-1). With the exact zero-order-hold stepping, B_IG is the
step's discrete gains matrix Γ_IG(u(k-1)) = ∫ exp(A(u) s) ds B_IG, computed by the same
kernel as the states (unit gains stepped from a zero state).

Rows with every zone temperature missing keep the previous estimate (no information);
partly missing rows use the zones that reported (minimum-norm solution if they do not
determine every zone's gain).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from zonecast.estimator.dataset import ModelData
from zonecast.estimator.gains import estimate_gains_step
from zonecast.estimator.integrate import ExactStepper
from zonecast.estimator.model import BilinearModel


@dataclass
class GainsTrack:
    """Per-step internal gains of a span and the states they imply.

    Attributes
    ----------
    f_ig : (N, n_zones) f_IG(k) [W/m2] acting over row k's interval (estimated from ȳ(k+1))
    x : (N + 1, n) states [degC]; C x(k) equals ȳ(k) where the zone was measured
    cb : (N, n_zones, n_zones) C Γ_IG(u(k)) [K per W/m2]
    """

    f_ig: np.ndarray
    x: np.ndarray
    cb: np.ndarray


def stepper_for(model: BilinearModel, u: np.ndarray) -> ExactStepper:
    """An :class:`ExactStepper` of ``model`` valid for airflows up to the max of ``u``."""
    return ExactStepper(model.structure.A(model.params.physical), model._rooms, model._bxu,
                        model.step, np.max(u, axis=0), capacity=model.structure.capacity,
                        ret=model._ret, retc=model._retc, switched=model.switched)


def track_gains(model: BilinearModel, data: ModelData, start: int, stop: int,
                x0: np.ndarray, stepper: ExactStepper | None = None) -> GainsTrack:
    """Estimate f_IG over rows [start, stop) of ``data`` from the initial state ``x0``."""
    st = stepper or stepper_for(model, data.u[start:stop])
    nz, n = model.n_zones, model.n
    base = (data.v[start:stop] @ model.Bv.T + model.params.c_ig @ model.B_ig.T
            + model.reheat_forcing(data.u[start:stop], data.reheat[start:stop]))
    N = stop - start
    modes = model.modes(data.u[start:stop], data.reheat[start:stop])
    f = np.zeros((N, nz))
    cb = np.zeros((N, nz, nz))
    xs = np.empty((N + 1, n))
    xs[0] = x0
    x = np.asarray(x0, float)
    prev = np.zeros(nz)
    for i in range(N):
        k = start + i
        mode = None if modes is None else modes[i]
        xt = st.step(x, data.u[k], base[i], data.v[k, 1], mode)
        gam = st.columns(data.u[k], model.B_ig, mode)
        cb[i] = model.C @ gam
        y_meas = data.y[k + 1] if k + 1 < len(data) else np.full(nz, np.nan)
        if np.isfinite(y_meas).any():
            prev = estimate_gains_step(cb[i], y_meas, model.C @ xt,
                                       rank_deficient="min_norm").f_ig
        f[i] = prev
        x = xt + gam @ prev
        xs[i + 1] = x
    return GainsTrack(f, xs, cb)


def zone_gain_heat(f_ig: np.ndarray, c_ig: np.ndarray, zone_area: np.ndarray) -> np.ndarray:
    """Internal gains heat per zone [W]: a_floor (c_IG + f_IG) (paper eq:q_ig)."""
    return (np.asarray(f_ig) + np.asarray(c_ig)) * np.asarray(zone_area)


def truth_column(columns, part: str, key: str) -> str:
    """The column of a campaign's ``truth.csv`` (docs/data.md) with ``part``'s heat [W] at
    ``key`` (a room, or ``zone:<zone>``): for people their sensible heat where the campaign
    has it (``people_sensible:``; the latent part only moistens the air and is no heat of
    the air balance the model keeps), else the column of the part's own name (``people:``
    is sensible + latent heat)."""
    if part == "people" and f"people_sensible:{key}" in columns:
        return f"people_sensible:{key}"
    return f"{part}:{key}"


def truth_correlation(est: np.ndarray, true: np.ndarray) -> dict:
    """Pearson r and least-squares scale (true ≈ scale · est) over rows where both exist."""
    ok = np.isfinite(est) & np.isfinite(true)
    e, t = est[ok], true[ok]
    if len(e) < 3 or np.std(e) == 0 or np.std(t) == 0:
        return {"r": float("nan"), "scale": float("nan"), "n": len(e)}
    return {"r": float(np.corrcoef(e, t)[0, 1]), "scale": float(np.dot(e, t) / np.dot(e, e)),
            "n": len(e)}
