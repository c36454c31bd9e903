"""Error statistics as the paper reports them: RMS per zone and their mean (Tables 2, 3),
RMS versus prediction horizon (Fig. 3)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def rms_by_zone(pred: np.ndarray, meas: np.ndarray, zones: Sequence[str]) -> dict[str, float]:
    """RMS [K] of ``pred - meas`` per zone over the rows where both are finite, plus
    ``mean``: the mean of the zone RMS values, as the paper's "Mean" column.

    Parameters
    ----------
    pred, meas : (N, n_zones) [degC]
    zones : zone names in column order
    """
    pred, meas = np.asarray(pred, float), np.asarray(meas, float)
    if pred.shape != meas.shape or pred.shape[-1] != len(zones):
        raise ValueError(f"pred {pred.shape} and meas {meas.shape} must both be (N, {len(zones)})")
    err = pred - meas
    out = {}
    for j, z in enumerate(zones):
        e = err[:, j][np.isfinite(err[:, j])]
        out[z] = float(np.sqrt(np.mean(e**2))) if len(e) else float("nan")
    out["mean"] = float(np.nanmean([out[z] for z in zones]))
    return out


def horizon_rms(pred: np.ndarray, meas: np.ndarray, zones: Sequence[str]) -> dict[str, list[float]]:
    """RMS [K] per zone for each forecast lead.

    Parameters
    ----------
    pred, meas : (n_forecasts, H, n_zones) [degC]; lead h = h + 1 steps after issue.

    Returns
    -------
    zone -> list of H RMS values, plus ``mean`` (mean over zones per lead).
    """
    pred, meas = np.asarray(pred, float), np.asarray(meas, float)
    if pred.shape != meas.shape or pred.ndim != 3:
        raise ValueError(f"pred {pred.shape} and meas {meas.shape} must be (n_forecasts, H, n_zones)")
    err2 = (pred - meas) ** 2
    with np.errstate(invalid="ignore"):
        per = np.sqrt(np.nanmean(err2, axis=0))  # (H, n_zones)
    out = {z: per[:, j].tolist() for j, z in enumerate(zones)}
    out["mean"] = np.nanmean(per, axis=1).tolist()
    return out
