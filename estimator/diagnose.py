"""Sim-to-real diagnosis: where the model's error lies, which unmodelled effect causes it, and
how much it shrinks once the effect is added, on weeks withheld from the search.

Pipeline (docs/diagnosis.md has the method and the measured numbers):

1. :func:`baseline` — the model's 24-h forecasts with the fixed internal-gains profile (paper
   Eq:fixed_ig fitted on the training weeks), issued every local midnight, on every week, and
   a week-long open-loop simulation; residuals = measured − model. The state at an issue is
   the gains tracker's (paper Eq:ig(k-1) every step from x_KF after the week's first day:
   its zone temperatures equal the measured ones), which reads nothing after the issue and is
   ten times cheaper than a Kalman filter over the previous day.
2. :func:`where` — the residuals by zone, hour of day, weekday/weekend, season, operating
   regime (airflow above minimum or not, airflow level, solar level, outdoor temperature,
   excitation vs normal operation) and forecast lead.
3. :func:`sensitivities` — for every candidate effect of :mod:`.effects`, zone and variant,
   the change of the forecasts per unit of its parameter (exact for the heat and output
   terms given the base prediction, a secant for the furniture-area scaling). Heat terms
   are taken net of their training-week time-of-week mean: a refitted weekly profile would
   absorb that part.
4. :func:`score_candidates` — each candidate's parameter fitted by least squares on the
   training weeks' residuals; its score is the share of the training sum of squares it
   removes under leave-one-week-out cross-validation, its confidence a one-sided t-test over
   the per-day reductions (days are roughly independent; 15-min residuals are not).
5. :func:`diagnose` — effects ranked by score (ties between confident effects to the one
   with fewer parameters, :func:`_rank`); each with its confident zones refitted on all
   training weeks and scored on the held-out weeks, which no step above has read. With a
   :class:`Reference` the base keeps the reference period's profile and adds its effects.
6. :func:`forward_selection` — from the ranking's first effect, which others are still
   confident once it is in the model (refitted together); the best of them is added next.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
import scipy.sparse as sp
from scipy import optimize, stats
from zonecast.estimator.dataset import ModelData
from zonecast.estimator.effects import (
    GAINS_PROFILE,
    SCHEDULE,
    SPECS,
    adjacent_rooms,
    box_zone_matrix,
    exchange_pairs,
    heat_regressor,
    interzone_exchange,
    minimum_airflow_fraction,
    time_of_week_mean,
)
from zonecast.estimator.forecast import (
    HORIZON,
    fill_profile,
    fixed_profile,
    issue_rows,
    track_week,
    week_split,
    zone_floor_area,
)
from zonecast.estimator.gains import WeeklyProfile
from zonecast.estimator.internal_gains import stepper_for
from zonecast.estimator.model import BilinearModel, build_model

__all__ = [
    "CONFIDENCE",
    "FORWARD_STEPS",
    "MIN_SCORE",
    "TIE_CONFIDENCE",
    "Baseline",
    "Candidate",
    "Diagnosis",
    "Reference",
    "baseline",
    "bias_offset_states",
    "diagnose",
    "exchanged_air",
    "forward_selection",
    "furniture_rebuilder",
    "load_reference",
    "reference_terms",
    "scaled_internal_mass",
    "score_candidates",
    "sensitivities",
    "where",
]

#: a candidate is a confident attribution when its cross-validated confidence and score
#: reach these (set before the blind benchmark was run; docs/diagnosis.md)
CONFIDENCE = 0.99
MIN_SCORE = 0.02
#: two confident effects are tied when the better one's per-day reductions exceed the
#: other's with less than this one-sided confidence (then the simpler one ranks first)
TIE_CONFIDENCE = 0.95
#: effects the forward selection adds at most (the ranking's first included)
FORWARD_STEPS = 3
#: smallest relative area change of the thermal-mass secant (its first step)
MASS_STEP = 0.1
#: state kinds whose area the thermal-mass effect scales
MASS_KINDS = ("internal_mass",)
#: iterations of the thermal-mass secant towards the change the training weeks ask for
MASS_SECANTS = 4
#: range of the relative area change θ searched (the area times 1 + θ)
MASS_SCALE_RANGE = (-0.9, 9.0)
#: first conductance of the interzone-exchange secant, per pair of rooms [W/K]
EXCHANGE_STEP = 10.0
#: largest conductance per pair of rooms searched [W/K] (c_p·ṁ of about 0.8 m3/s)
EXCHANGE_MAX = 1000.0


class DiagnosisError(ValueError):
    """The data cannot be diagnosed as asked (too few weeks, no forecasts)."""


# --------------------------------------------------------------------------- baseline


@dataclass
class Baseline:
    """Base forecasts and simulation of the model on every week.

    Attributes
    ----------
    split : dict from :func:`~.forecast.week_split` (training / held-out weeks)
    profile : WeeklyProfile used as f_IG [W/m2]
    issues : issue rows (local midnights from each week's second day)
    horizon : (n_issues,) steps forecast from each issue
    x0 : (n_issues, n) filtered states at the issues [degC]
    pred : (N, n_zones) forecast of row k from its issue (NaN outside forecasts) [degC]
    lead : (N,) steps since the issue (0 outside forecasts)
    issue_of_row : (N,) index into ``issues`` (-1 outside forecasts)
    sim : (N, n_zones) week-long open-loop simulation from x_KF after each week's first day
    week_of_row : (N,) week index (-1 outside whole weeks)
    """

    split: dict
    profile: WeeklyProfile
    issues: list[int]
    horizon: np.ndarray
    x0: np.ndarray
    pred: np.ndarray
    lead: np.ndarray
    issue_of_row: np.ndarray
    sim: np.ndarray
    week_of_row: np.ndarray
    gains: str = "profile"

    def rows_of(self, weeks: Sequence[int]) -> np.ndarray:
        """Boolean (N,) mask of forecast rows in the given weeks."""
        return np.isin(self.week_of_row, list(weeks)) & (self.lead > 0)


def _profile_at(profile: WeeklyProfile, times) -> np.ndarray:
    return np.nan_to_num(profile(times))


def baseline(model: BilinearModel, data: ModelData, *, seed: int = 0, gains: str = "profile",
             profile: WeeklyProfile | None = None,
             progress: Callable[[str], None] | None = None) -> Baseline:
    """Forecast and simulate the model on every week (see the module docstring).

    ``gains="profile"``: f_IG is the weekly profile fitted on the training weeks (paper
    Eq:fixed_ig); ``"constant"``: f_IG = 0 (only the model's c_IG), the identification's
    model. ``profile`` given: that profile (a reference period's, :func:`diagnose`), kept
    fixed; ``gains`` is then ``"reference"``.
    """
    if profile is not None:
        gains = "reference"
    elif gains not in ("profile", "constant"):
        raise ValueError(f"gains must be 'profile' or 'constant', got {gains!r}")
    split = week_split(data, seed)
    weeks = split["weeks"]
    N, nz = len(data), model.n_zones
    step = data.times[1] - data.times[0]
    say = progress or (lambda m: None)
    tracks = []
    for w in weeks:
        say(f"tracking the state, week {w['index'] + 1}/{len(weeks)}")
        tracks.append(track_week(model, data, w["rows"]))
    if gains == "reference":
        profile = fill_profile(profile)
    elif gains == "profile":
        profile = fixed_profile(data, [tracks[i] for i in split["train"]])
    else:
        nb = int(pd.Timedelta("7D") / step)
        profile = fill_profile(WeeklyProfile(np.zeros((nb, nz)), np.zeros(nb, int),
                                             data.timezone, step))
    week_of_row = np.full(N, -1)
    pred = np.full((N, nz), np.nan)
    sim = np.full((N, nz), np.nan)
    lead = np.zeros(N, int)
    issue_of_row = np.full(N, -1)
    issues, horizons, x0s = [], [], []
    for w, tr in zip(weeks, tracks):
        a, b = w["rows"]
        week_of_row[a:b] = w["index"]
        say(f"base forecasts, week {w['index'] + 1}/{len(weeks)}")
        for r in issue_rows(data, (a, b)):
            H = min(HORIZON, b - 1 - r)
            if H < 1 or r < tr.start:
                continue
            x0 = tr.track.x[r - tr.start]
            f = _profile_at(profile, data.times[r:r + H])
            pred[r + 1:r + 1 + H] = model.simulate(x0, data.u[r:r + H], data.v[r:r + H], f,
                                                   reheat=data.reheat[r:r + H]).y[1:]
            lead[r + 1:r + 1 + H] = np.arange(1, H + 1)
            issue_of_row[r + 1:r + 1 + H] = len(issues)
            issues.append(r)
            horizons.append(H)
            x0s.append(x0)
        s0 = tr.start
        f = _profile_at(profile, data.times[s0:b])
        sim[s0:b] = model.simulate(tr.track.x[0], data.u[s0:b], data.v[s0:b], f,
                                   reheat=data.reheat[s0:b]).y[:-1]
    if not issues:
        raise DiagnosisError("no forecast could be issued: the data need whole weeks with "
                             "local midnights after their first day")
    return Baseline(split, profile, issues, np.array(horizons), np.array(x0s), pred, lead,
                    issue_of_row, sim, week_of_row, gains)


# --------------------------------------------------------------------------- sensitivities


def _link_scaled(M: sp.spmatrix, inside: np.ndarray, scale: float) -> sp.csr_matrix:
    """``M`` (rows: d/dt of each state) with the links of the states outside the set to the
    states inside it multiplied by ``scale`` and the outside states' diagonals adjusted so
    that each row still sums as before plus the extra conductance's loss."""
    M = sp.csr_matrix(M)
    out_rows = sp.diags((~inside).astype(float))
    L = out_rows @ M @ sp.diags(inside.astype(float))
    extra = (scale - 1.0) * L
    return (M + extra - sp.diags(np.asarray(extra.sum(axis=1)).ravel())).tocsr()


def scaled_internal_mass(model: BilinearModel, states: np.ndarray, scale: float) -> BilinearModel:
    """The model with the area of the internal mass whose nodes are ``states`` multiplied by
    ``scale`` [-]: their heat capacities and every conductance they have to the rest of the
    network (the room's air, other faces) scale together. The set's own rows of A are
    unchanged (capacity and conductance both scale); each other node's link to the set is
    multiplied by ``scale``, with its diagonal adjusted (it now loses that much more heat)."""
    st = model.structure
    inside = np.zeros(model.n, bool)
    inside[np.asarray(states, int)] = True
    if scale <= 0:
        raise ValueError(f"the internal-mass area scale must be > 0, got {scale}")
    capacity = st.capacity.copy()
    capacity[inside] *= scale
    new = dataclasses.replace(
        st, capacity=capacity, A0=_link_scaled(st.A0, inside, scale),
        A_p=[_link_scaled(a, inside, scale) for a in st.A_p])
    return BilinearModel(new, model.params, model.step, model.method, model.u_nominal,
                         reheat_scale=model.reheat_scale,
                         reheat_from_faces=model.reheat_from_faces)


def exchanged_air(model: BilinearModel, j: int, conductance: float) -> BilinearModel:
    """The model with air exchanged both ways between each room of zone ``j`` and each
    adjacent room of another zone (:func:`~.effects.adjacent_rooms`): a conductance
    ``conductance`` = c_p·ṁ [W/K] per pair of rooms between their air states, as
    EnergyPlus's ZoneCrossMixing moves the same flow each way. Heat is conserved: A's
    capacity-weighted rows still sum as before."""
    if conductance < 0:
        raise ValueError(f"the exchange conductance must be >= 0 W/K, got {conductance}")
    st = model.structure
    nr = len(st.rooms)
    adj = adjacent_rooms(model)
    mine = np.isin(st.rooms, st.zones[list(st.zones)[j]])
    pairs = np.outer(mine, ~mine) * adj
    G = conductance * (pairs + pairs.T)  # (n_rooms, n_rooms) W/K
    L = np.diag(G.sum(axis=1)) - G  # the exchange's Laplacian
    D = sp.lil_matrix((model.n, model.n))
    D[:nr, :nr] = -L / st.capacity[:nr, None]
    new = dataclasses.replace(st, A0=(st.A0 + D.tocsr()).tocsr())
    return BilinearModel(new, model.params, model.step, model.method, model.u_nominal,
                         reheat_scale=model.reheat_scale,
                         reheat_from_faces=model.reheat_from_faces)


def furniture_rebuilder(building, zones: Mapping[str, Sequence[str]], boxes: Mapping[str, str],
                        model: BilinearModel) -> Callable[[int, float], BilinearModel]:
    """``f(j, scale)``: ``model`` rebuilt from ``building`` (:func:`~.model.build_model`, the
    model's own options and parameters) with the area of every InternalMass of zone j's
    rooms multiplied by ``scale``: capacity, links to the room, and the shares of window
    solar and radiant gains its faces take (the other faces' shares fall as EnergyPlus's
    would) all follow, as in the building. The state layout is the model's."""
    names = list(model.structure.zones)
    opts = model.structure.options

    def rebuild(j: int, scale: float) -> BilinearModel:
        rooms = {r.lower() for r in model.structure.zones[names[j]]}
        masses = {n: dataclasses.replace(m, area=m.area * scale) if m.zone.lower() in rooms
                  else m for n, m in building.internal_masses.items()}
        b = dataclasses.replace(building, internal_masses=masses)
        new = build_model(b, zones, boxes, model.params, options=opts, step=model.step,
                          method=model.method, u_nominal=model.u_nominal)
        if new.n != model.n or [lab.kind for lab in new.structure.labels] != \
                [lab.kind for lab in model.structure.labels]:
            raise DiagnosisError("the model rebuilt from the building has another state "
                                 "layout than the model diagnosed: give the building the "
                                 "model was built from")
        return new

    return rebuild


def _forecast_windows(base: Baseline):
    for i, (r, H) in enumerate(zip(base.issues, base.horizon)):
        yield i, r, int(H)


def _heat_response(model: BilinearModel, data: ModelData, base: Baseline, q: np.ndarray,
                   stepper) -> np.ndarray:
    """(N, nz, nz) zone outputs per zone-source of heat ``q`` (N, nz) [W], from zero state
    at every issue (superposition: the forecasts' change when q is added)."""
    nz, n = model.n_zones, model.n
    area = zone_floor_area(model)
    out = np.full((len(data), nz, nz), np.nan)
    bcols = model.B_ig / area[None, :]
    for _, r, H in _forecast_windows(base):
        # every zone's source at once: one compiled run per window (each column the same
        # arithmetic as its own run of H single steps)
        qw = q[r:r + H]
        xs = stepper.run_columns(np.zeros((n, nz)), data.u[r:r + H], bcols,
                                 np.where(np.isfinite(qw), qw, 0.0), np.zeros(H),
                                 model.modes(data.u[r:r + H], data.reheat[r:r + H]))
        out[r + 1:r + H + 1] = np.einsum("zi,kij->kzj", model.C, xs[1:])
    return out


def sensitivities(model: BilinearModel, data: ModelData, base: Baseline,
                  effects: Sequence[str] | None = None,
                  progress: Callable[[str], None] | None = None, *,
                  net_of_profile: bool | None = None,
                  heating_setpoint: np.ndarray | None = None,
                  mass_model: Callable[[int, float], BilinearModel] | None = None) -> dict:
    """Forecast sensitivities of every candidate.

    ``heating_setpoint`` (N,) [degC]: the site's scheduled heating set point; without it
    the reheat variant ``"schedule"`` is left out.

    ``net_of_profile``: heat terms net of their training-week time-of-week mean (what a
    profile refitted on these weeks absorbs); default: when the base fits its profile here
    (``base.gains == "profile"``).

    Returns
    -------
    dict
        (effect, variant) -> (N, n_zones, n_zones) array: ``[k, i, j]`` is the change of
        zone i's forecast at row k per unit of zone j's parameter.
    """
    effects = list(effects or SPECS)
    unknown = [e for e in effects if e not in SPECS]
    if unknown:
        raise DiagnosisError(f"unknown effects {unknown}; known: {list(SPECS)}")
    train_rows = np.flatnonzero(np.isin(base.week_of_row, base.split["train"]))
    net = base.gains == "profile" if net_of_profile is None else net_of_profile
    stepper = stepper_for(model, data.u)
    temps = np.where(np.isfinite(base.pred), base.pred, base.sim)
    # rows before a week's first issue: the measurement of that row, else the training mean
    temps = np.where(np.isfinite(temps), temps, data.y)
    temps = np.where(np.isfinite(temps), temps, np.nanmean(data.y[train_rows], axis=0)[None, :])
    # the base's internal gains (W/m2) for the gains-shaped variant, offered against a
    # reference period's profile only: a profile refitted here absorbs its time-of-week
    # pattern, and against constant gains it would be a constant heat, which mimics a
    # sensor offset
    gains = (model.params.c_ig[None, :] + _profile_at(base.profile, data.times)
             if base.gains == "reference" and not net else None)
    out = {}
    for e in effects:
        spec = SPECS[e]
        if progress:
            progress(f"sensitivities: {e}")
        for var in spec.variants:
            if var == SCHEDULE and heating_setpoint is None:
                continue
            if var == GAINS_PROFILE and gains is None:
                continue
            if e == "interzone_air":
                out[(e, var)] = _exchange_response(model, data, base, temps, stepper,
                                                   train_rows if net else None)
            elif spec.kind == "heat":
                q = heat_regressor(e, var, model, data, temps, heating_setpoint, gains)
                if net:
                    q = q - time_of_week_mean(q, data, train_rows)
                out[(e, var)] = _heat_response(model, data, base, q, stepper)
            elif spec.kind == "output":
                out[(e, var)] = _bias_response(model, data, base, stepper)
            else:
                out[(e, var)] = _mass_response(model, data, base, mass_model)
    return out


def _exchange_response(model: BilinearModel, data: ModelData, base: Baseline,
                       temps: np.ndarray, stepper, train_rows: np.ndarray | None) -> np.ndarray:
    """(N, nz, nz) forecast change per unit interzone exchange of each zone [K per W/K]:
    the secant of the forecasts of :func:`exchanged_air` (the exchange changes the network,
    and strong mixing shrinks the very differences that drive it, so the first-order heat
    overstates it), iterated towards the conductance the training residuals ask for as
    :func:`_secant_columns`. With ``train_rows`` (a profile refitted on these weeks) the
    response to the training-week time-of-week mean of the linearised exchange heat
    (:func:`~.effects.interzone_exchange`) is taken off: what the profile absorbs. A zone
    without an adjacent room of another zone has a zero column."""
    pairs = exchange_pairs(model)
    has = pairs.sum(axis=1) > 0
    out = _secant_columns(model, data, base, lambda j, t: exchanged_air(model, j, t), has,
                          EXCHANGE_STEP, (EXCHANGE_STEP, EXCHANGE_MAX), MASS_SECANTS)
    if train_rows is not None:
        Q = interzone_exchange(pairs, temps)
        for j in np.flatnonzero(has):
            m = time_of_week_mean(Q[:, :, j], data, train_rows)
            out[:, :, j] -= _heat_response(model, data, base, m, stepper).sum(axis=2)
    out[~np.isfinite(base.pred).all(axis=1)] = np.nan
    return out


def _zone_states(model: BilinearModel, kinds: Sequence[str]) -> list[np.ndarray]:
    st = model.structure
    zone_of_room = {r: j for j, z in enumerate(st.zones) for r in st.zones[z]}
    out = []
    for j in range(model.n_zones):
        out.append(np.array([i for i, lab in enumerate(st.labels)
                             if lab.kind in kinds and zone_of_room.get(lab.room) == j]))
    return out


def bias_offset_states(model: BilinearModel, u: np.ndarray) -> np.ndarray:
    """(n, n_zones) state offset that a unit sensor offset of each zone leaves in a state
    tracked by paper Eq:ig(k-1): the tracker keeps the zone's modelled air at the offset
    reading with extra gains, and after long enough the whole state carries the steady
    response to them, S (C S)^-1 with S = -A(u)^-1 B_IG (``u``: the airflows then)."""
    S = -np.linalg.solve(model.system_matrix(u), model.B_ig)
    return S @ np.linalg.inv(model.C @ S)


def _bias_response(model: BilinearModel, data: ModelData, base: Baseline, stepper) -> np.ndarray:
    """A sensor offset θ_j: ȳ_j = C_j x + θ_j. The gains tracker carries the offset into the
    state at the issue (:func:`bias_offset_states`); the model then relaxes it, so the
    forecast error is θ_j (e_j − C x_δ(h)) with x_δ the free response from that offset."""
    nz = model.n_zones
    out = np.full((len(data), nz, nz), np.nan)
    for _, r, H in _forecast_windows(base):
        X0 = bias_offset_states(model, data.u[r])
        xs = stepper.run_columns(X0, data.u[r:r + H], np.zeros((model.n, nz)),
                                 np.zeros((H, nz)), np.zeros(H),
                                 model.modes(data.u[r:r + H], data.reheat[r:r + H]))
        cols = -np.einsum("zi,kij->kzj", model.C, xs[1:])
        cols[:, np.arange(nz), np.arange(nz)] += 1.0
        out[r + 1:r + H + 1] = cols
    return out


def _mass_response(model: BilinearModel, data: ModelData, base: Baseline,
                   mass_model: Callable[[int, float], BilinearModel] | None = None
                   ) -> np.ndarray:
    """Secant of the forecasts in the area of each zone's internal mass (1 + θ; the model
    from ``mass_model``, :func:`furniture_rebuilder`, else :func:`scaled_internal_mass`),
    iterated as :func:`_secant_columns` within :data:`MASS_SCALE_RANGE`: the response is
    far from linear (a tripled furniture area is not 20 steps of 10 %). A zone without
    internal mass has a zero column (no term)."""
    states = _zone_states(model, MASS_KINDS)

    def make(j: int, theta: float) -> BilinearModel:
        return (mass_model(j, 1.0 + theta) if mass_model is not None
                else scaled_internal_mass(model, states[j], 1.0 + theta))

    return _secant_columns(model, data, base, make, np.array([len(s) > 0 for s in states]),
                           MASS_STEP, MASS_SCALE_RANGE, MASS_SECANTS)


def _secant_columns(model: BilinearModel, data: ModelData, base: Baseline,
                    make: Callable[[int, float], BilinearModel], has: np.ndarray,
                    step: float, bounds: tuple[float, float], secants: int) -> np.ndarray:
    """(N, nz, nz) secants of the forecasts in a parameter θ_j that changes the model
    (``make(j, θ)``): the forecasts' change at θ divided by θ, from every issue's state
    with the base's internal gains. θ starts at ``step`` and is iterated towards the change
    the training weeks' residuals ask for (least squares of the residuals on the secant,
    ``secants`` times, within ``bounds``, never nearer zero than ``step``); the column is
    the secant there, so a fitted parameter near that θ reproduces the changed model's
    forecasts. Zones where ``has`` is False get a zero column."""
    nz = model.n_zones
    out = np.full((len(data), nz, nz), np.nan)
    windows = list(_forecast_windows(base))
    for _, r, H in windows:
        out[r + 1:r + 1 + H] = 0.0
    train = base.rows_of(base.split["train"])
    resid = data.y - base.pred

    gains = _profile_at(base.profile, data.times)

    def change(j: int, theta: float) -> np.ndarray:
        m = make(j, theta)
        d = np.full((len(data), nz), np.nan)
        if m.method != "exact":
            for i, r, H in windows:
                y = m.simulate(base.x0[i], data.u[r:r + H], data.v[r:r + H], gains[r:r + H],
                               reheat=data.reheat[r:r + H]).y[1:]
                d[r + 1:r + 1 + H] = y - base.pred[r + 1:r + 1 + H]
            return d
        # one stepper for every window (its set-up, the spectral bound, done once per
        # model): the same exact stepping as ``m.simulate`` window by window
        stepper = stepper_for(m, data.u)
        forcing = (data.v @ m.Bv.T + (m.params.c_ig + gains) @ m.B_ig.T
                   + m.reheat_forcing(data.u, data.reheat))
        modes = m.modes(data.u, data.reheat)
        for i, r, H in windows:
            xs = stepper.run(base.x0[i], data.u[r:r + H], forcing[r:r + H], data.v[r:r + H, 1],
                             None if modes is None else modes[r:r + H])
            d[r + 1:r + 1 + H] = xs[1:] @ m.C.T - base.pred[r + 1:r + 1 + H]
        return d

    lo, hi = bounds
    for j in np.flatnonzero(has):
        theta = step
        col = change(j, theta) / theta
        for _ in range(secants):
            ok = train[:, None] & np.isfinite(col) & np.isfinite(resid)
            den = float((col[ok] ** 2).sum())
            if den <= 0:
                break
            new = float(np.clip((col[ok] * resid[ok]).sum() / den, lo, hi))
            new = float(np.sign(new) or 1.0) * max(abs(new), step)
            if abs(new - theta) <= 0.02 * max(abs(theta), step):
                break
            theta = new
            col = change(j, theta) / theta
        out[:, :, j] = np.where(np.isfinite(col), col, out[:, :, j])
    return out


# --------------------------------------------------------------------------- scoring


@dataclass
class Candidate:
    """One effect in a set of zones, fitted and scored.

    Attributes
    ----------
    effect, variant : the effect and its searched hyper-parameter (setpoint, lag) or None
    zones : zone names with a parameter
    parameters : zone -> fitted value on all training weeks [effect's unit]
    score : share of the training sum of squares removed under leave-one-week-out fits
    confidence : 1 − p of a one-sided t-test of the per-day reductions
    heldout_rms_before, heldout_rms_after : zone -> RMS on the held-out weeks, + ``mean``
    """

    effect: str
    variant: float | None
    zones: list[str]
    parameters: dict[str, float]
    score: float
    confidence: float
    n_days: int
    heldout_rms_before: dict[str, float] = field(default_factory=dict)
    heldout_rms_after: dict[str, float] = field(default_factory=dict)
    #: the same variant fitted in every zone (for a confident effect): what a reference
    #: period hands on (:func:`reference_terms`)
    parameters_all_zones: dict[str, float] = field(default_factory=dict)
    #: number of fitted parameters (zones, or 1 for a system-wide effect)
    n_params: int = 1
    #: effects ranked below this one that explain the training residuals as well (paired
    #: test of the per-day reductions not significant, :data:`TIE_CONFIDENCE`)
    tied_with: list[str] = field(default_factory=list)
    #: per-day SSE reductions under leave-one-week-out fits (training days, fixed order)
    day_reductions: np.ndarray | None = field(default=None, repr=False, compare=False)

    @property
    def confident(self) -> bool:
        return self.confidence >= CONFIDENCE and self.score >= MIN_SCORE

    def to_dict(self) -> dict:
        spec = SPECS[self.effect]
        return {"effect": self.effect, "variant": self.variant, "zones": self.zones,
                "parameters": self.parameters, "unit": spec.unit,
                "score": self.score, "confidence": self.confidence,
                "confident": self.confident, "n_days": self.n_days,
                "heldout_rms_before": self.heldout_rms_before,
                "heldout_rms_after": self.heldout_rms_after,
                "parameters_all_zones": self.parameters_all_zones,
                "n_params": self.n_params, "scope": spec.scope,
                "statistically_tied_with": self.tied_with}


def _fit(S: np.ndarray, r: np.ndarray, sign: int) -> np.ndarray:
    """Least squares θ for r ≈ S θ (rows with NaN dropped); θ ≥ 0 when ``sign`` is +1."""
    ok = np.isfinite(r) & np.isfinite(S).all(axis=1)
    if not ok.any():
        return np.zeros(S.shape[1])
    A, b = S[ok], r[ok]
    if sign > 0:
        return optimize.nnls(A, b)[0]
    return np.linalg.lstsq(A, b, rcond=None)[0]


def _flat(base: Baseline, sens: np.ndarray, resid: np.ndarray, rows: np.ndarray, zones_idx):
    """Stack rows x zones into a design matrix (one column per parameter zone)."""
    S = sens[rows][:, :, zones_idx].reshape(-1, len(zones_idx))
    r = resid[rows].reshape(-1)
    return S, r


def _day_reductions(base: Baseline, sens, resid, cols, sign, train_weeks) -> tuple[np.ndarray, float]:
    """Per-day SSE reductions with θ fitted on the other training weeks, and base SSE."""
    red = []
    total = 0.0
    for w in train_weeks:
        fit_rows = base.rows_of([x for x in train_weeks if x != w])
        S, r = _flat(base, sens, resid, fit_rows, cols)
        theta = _fit(S, r, sign)
        test = np.flatnonzero(base.rows_of([w]))
        for i in np.unique(base.issue_of_row[test]):
            rows = test[base.issue_of_row[test] == i]
            e0 = resid[rows]
            e1 = e0 - sens[rows][:, :, cols] @ theta
            ok = np.isfinite(e0) & np.isfinite(e1)
            sse0 = float(np.sum(e0[ok] ** 2))
            total += sse0
            red.append(sse0 - float(np.sum(e1[ok] ** 2)))
    return np.array(red), total


def _rms(e: np.ndarray, zones: Sequence[str]) -> dict[str, float]:
    out = {z: float(np.sqrt(np.nanmean(e[:, j] ** 2))) for j, z in enumerate(zones)}
    out["mean"] = float(np.mean([out[z] for z in zones]))
    return out


def _evaluate(base: Baseline, data: ModelData, sens: np.ndarray, resid: np.ndarray, effect: str,
              variant, cols: list[int], zones: Sequence[str]) -> Candidate:
    spec = SPECS[effect]
    train = base.split["train"]
    red, total = _day_reductions(base, sens, resid, cols, spec.sign, train)
    score = float(red.sum() / total) if total > 0 else 0.0
    if len(red) > 1 and red.std(ddof=1) > 0:
        t = red.mean() / (red.std(ddof=1) / np.sqrt(len(red)))
        conf = float(stats.t.cdf(t, len(red) - 1))
    else:
        conf = 0.0
    S, r = _flat(base, sens, resid, base.rows_of(train), cols)
    theta = _fit(S, r, spec.sign)
    if spec.scope == "system":  # ``sens`` is the zones' summed column: one θ for all
        return Candidate(effect, variant, list(zones), {z: float(theta[0]) for z in zones},
                         score, conf, len(red), n_params=1, day_reductions=red)
    return Candidate(effect, variant, [zones[c] for c in cols],
                     {zones[c]: float(t) for c, t in zip(cols, theta)}, score, conf, len(red),
                     n_params=len(cols), day_reductions=red)


def score_candidates(base: Baseline, data: ModelData, sens: dict, zones: Sequence[str],
                     resid: np.ndarray | None = None) -> dict[str, dict[str, Candidate]]:
    """Best variant of every effect in every zone: effect -> zone -> :class:`Candidate`."""
    resid = data.y - base.pred if resid is None else resid
    out: dict[str, dict[str, Candidate]] = {}
    for (effect, variant), s in sens.items():
        if SPECS[effect].scope == "system":
            # one parameter for every zone: the zones' responses to a common θ summed
            c = _evaluate(base, data, s.sum(axis=2, keepdims=True), resid, effect, variant,
                          [0], zones)
            for z in zones:
                best = out.setdefault(effect, {}).get(z)
                if best is None or c.score > best.score:
                    out[effect][z] = c
            continue
        for j, z in enumerate(zones):
            c = _evaluate(base, data, s, resid, effect, variant, [j], zones)
            best = out.setdefault(effect, {}).get(z)
            if best is None or c.score > best.score:
                out[effect][z] = c
    return out


def _heldout(base: Baseline, data: ModelData, sens: np.ndarray, resid: np.ndarray,
             cand: Candidate, zones: Sequence[str]) -> Candidate:
    rows = base.rows_of(base.split["validation"])
    cols = [list(zones).index(z) for z in cand.zones]
    theta = np.array([cand.parameters[z] for z in cand.zones])
    before = resid[rows]
    after = before - sens[rows][:, :, cols] @ theta
    cand.heldout_rms_before = _rms(before, zones)
    cand.heldout_rms_after = _rms(after, zones)
    return cand


def _rank(cands: list[Candidate]) -> list[Candidate]:
    """Confident effects first, by score; then, among the confident effects that explain
    the training residuals as well as the best one (paired one-sided t-test of their
    per-day reductions below :data:`TIE_CONFIDENCE`), the one with the fewest parameters
    comes first (parsimony: e.g. one system-wide supply offset against six zone sensor
    offsets that mimic it). ``tied_with`` of the first names the others of that group."""
    ranked = sorted(cands, key=lambda c: (c.confident, c.score), reverse=True)
    if not ranked or not ranked[0].confident:
        return ranked
    best = ranked[0]
    tied = [best]
    for c in ranked[1:]:
        if not c.confident or c.day_reductions is None or best.day_reductions is None:
            continue
        d = best.day_reductions - c.day_reductions
        if len(d) > 1 and d.std(ddof=1) > 0:
            conf = float(stats.t.cdf(d.mean() / (d.std(ddof=1) / np.sqrt(len(d))), len(d) - 1))
        else:
            conf = 0.0
        if conf < TIE_CONFIDENCE:
            tied.append(c)
    first = min(tied, key=lambda c: (c.n_params, -c.score))
    first.tied_with = [c.effect for c in tied if c is not first]
    return [first] + [c for c in ranked if c is not first]


# --------------------------------------------------------------------------- forward selection


def _solve_normal(H: np.ndarray, g: np.ndarray, nonneg: np.ndarray) -> np.ndarray:
    """argmin |A θ - b|² from H = A'A and g = A'b, with θ_i ≥ 0 where ``nonneg``: the same
    minimiser as on A and b, solved on the Cholesky factor of H (k x k)."""
    k = len(g)
    if k == 0:
        return np.zeros(0)
    Hr = H + 1e-12 * max(np.trace(H), 1e-300) / k * np.eye(k)
    if not nonneg.any():
        return np.linalg.lstsq(Hr, g, rcond=None)[0]
    L = np.linalg.cholesky(Hr)
    A2, b2 = L.T, np.linalg.solve(L, g)  # |A θ - b|² = |L' θ - L⁻¹ g|² + const
    if nonneg.all():
        return optimize.nnls(A2, b2)[0]
    lo = np.where(nonneg, 0.0, -np.inf)
    return optimize.lsq_linear(A2, b2, bounds=(lo, np.full(k, np.inf))).x


class _Given:
    """Leave-one-week-out fits of the terms already selected (the columns ``G`` (N, nz, m)):
    per training week, the residual of the other weeks' fit on that week's issues, and the
    base SSE the scores are shares of."""

    def __init__(self, base: Baseline, resid: np.ndarray, G: np.ndarray, nonneg: np.ndarray,
                 total: float):
        self.base, self.resid, self.G, self.nonneg, self.total = base, resid, G, nonneg, total
        m = G.shape[2]
        self.train = list(base.split["train"])
        self.folds = []
        for w in self.train + [None]:  # None: all training weeks (the reported parameters)
            fit_rows = base.rows_of([x for x in self.train if x != w])
            r = resid[fit_rows].reshape(-1)
            Gf = G[fit_rows].reshape(-1, m)
            ok = np.isfinite(r) & np.isfinite(Gf).all(axis=1)
            r, Gf = r[ok], Gf[ok]
            # rows of the flattened (N * nz, k) columns that enter this fit
            flat = np.flatnonzero(np.repeat(fit_rows, G.shape[1]))[ok]
            fold = {"flat": flat, "r": r, "G": Gf, "GG": Gf.T @ Gf, "Gr": Gf.T @ r}
            if w is not None:
                theta = _solve_normal(fold["GG"], fold["Gr"], nonneg)
                test = np.flatnonzero(base.rows_of([w]))
                fold["groups"] = [test[base.issue_of_row[test] == i]
                                  for i in np.unique(base.issue_of_row[test])]
                fold["e0"] = [resid[g] - G[g] @ theta for g in fold["groups"]]
            self.folds.append(fold)

    def _theta(self, fold: dict, C: np.ndarray, nonneg: np.ndarray) -> np.ndarray:
        Cf = C.reshape(-1, C.shape[2])[fold["flat"]]
        bad = ~np.isfinite(Cf).all(axis=1)
        if bad.any():  # rows without a sensitivity: left out of this fit
            Cf = np.where(bad[:, None], 0.0, Cf)
        GC = fold["G"].T @ Cf
        H = np.block([[fold["GG"], GC], [GC.T, Cf.T @ Cf]])
        g = np.concatenate([fold["Gr"], Cf.T @ fold["r"]])
        return _solve_normal(H, g, nonneg)

    def evaluate(self, C: np.ndarray, sign: int) -> tuple[float, float, int, np.ndarray]:
        """Score, confidence, days and θ (all training weeks) of the columns ``C`` (N, nz, k)
        added to the given terms, both refitted together in every fold."""
        m = self.G.shape[2]
        nonneg = np.concatenate([self.nonneg, np.full(C.shape[2], sign > 0)])
        red = []
        for fold in self.folds[:-1]:
            th = self._theta(fold, C, nonneg)
            for rows, e0 in zip(fold["groups"], fold["e0"]):
                e1 = self.resid[rows] - self.G[rows] @ th[:m] - C[rows] @ th[m:]
                ok = np.isfinite(e0) & np.isfinite(e1)
                red.append(float(np.sum(e0[ok] ** 2)) - float(np.sum(e1[ok] ** 2)))
        red = np.array(red)
        score = float(red.sum() / self.total) if self.total > 0 else 0.0
        if len(red) > 1 and red.std(ddof=1) > 0:
            t = red.mean() / (red.std(ddof=1) / np.sqrt(len(red)))
            conf = float(stats.t.cdf(t, len(red) - 1))
        else:
            conf = 0.0
        theta = self._theta(self.folds[-1], C, nonneg)
        return score, conf, len(red), theta[m:]


def _columns(sens: dict, effect: str, variant, cols: list[int]) -> np.ndarray:
    s = sens[(effect, variant)]
    if SPECS[effect].scope == "system":
        return s.sum(axis=2, keepdims=True)
    return s[:, :, cols]


def forward_selection(base: Baseline, sens: dict, resid: np.ndarray, ranked: list[Candidate],
                      zones: Sequence[str], max_steps: int = FORWARD_STEPS) -> dict:
    """Forward selection from the ranking's first effect: with the effects selected so far
    in the model (their parameters refitted with each candidate's in every leave-one-week-out
    fold), every other effect is scored again in every zone and variant as in
    :func:`score_candidates`, and in its confident zones together; the best confident one is
    added next. Scores stay shares of the base's training SSE, so a step's score is what the
    effect removes *beyond* the ones before it. Stops when nothing more is confident.

    Returns
    -------
    dict
        ``steps``: the selected effects in order (``effect``, ``variant``, ``zones``,
        ``parameters`` of the effect's own fit given the ones before, ``score``,
        ``confidence``); ``confident_after``: for k = 0, 1, ... effects selected, the effects
        still confident (k = 0: the ranking's confident effects).
    """
    zones = list(zones)
    out = {"steps": [], "confident_after": [[c.effect for c in ranked if c.confident]]}
    if not ranked or not ranked[0].confident:
        return out
    top = ranked[0]
    total = 0.0
    for w in base.split["train"]:
        e = resid[base.rows_of([w])]
        total += float(np.nansum(e ** 2))
    cols = [zones.index(z) for z in top.zones]
    G = _columns(sens, top.effect, top.variant, cols)
    nonneg = np.full(G.shape[2], SPECS[top.effect].sign > 0)
    chosen = [top.effect]
    out["steps"].append({"effect": top.effect, "variant": top.variant, "zones": top.zones,
                         "parameters": top.parameters, "score": top.score,
                         "confidence": top.confidence})
    while True:
        given = _Given(base, resid, G, nonneg, total)
        best_by_effect = {}
        for (effect, variant), s in sens.items():
            if effect in chosen:
                continue
            spec = SPECS[effect]
            per_zone = best_by_effect.setdefault(effect, {})
            if spec.scope == "system":
                sc, cf, _, th = given.evaluate(s.sum(axis=2, keepdims=True), spec.sign)
                if "*" not in per_zone or sc > per_zone["*"][0]:
                    per_zone["*"] = (sc, cf, variant, [0], th)
                continue
            for j, z in enumerate(zones):
                sc, cf, _, th = given.evaluate(s[:, :, [j]], spec.sign)
                if z not in per_zone or sc > per_zone[z][0]:
                    per_zone[z] = (sc, cf, variant, [j], th)
        picks = []
        for effect, per_zone in best_by_effect.items():
            conf = {z: v for z, v in per_zone.items() if v[1] >= CONFIDENCE and v[0] >= MIN_SCORE}
            if not conf:
                continue
            if "*" in conf or len(conf) == 1:
                sc, cf, variant, c, th = next(iter(conf.values()))
                zs = zones if "*" in conf else list(conf)
            else:
                variant = max(conf.values(), key=lambda v: v[0])[2]
                c = [zones.index(z) for z in conf]
                sc, cf, _, th = given.evaluate(sens[(effect, variant)][:, :, c],
                                               SPECS[effect].sign)
                zs = list(conf)
            if cf >= CONFIDENCE and sc >= MIN_SCORE:
                picks.append((sc, cf, effect, variant, zs, c, th))
        picks.sort(key=lambda p: p[0], reverse=True)
        out["confident_after"].append([p[2] for p in picks])
        if not picks or len(out["steps"]) >= max_steps:
            return out
        sc, cf, effect, variant, zs, c, th = picks[0]
        params = ({z: float(th[0]) for z in zones} if SPECS[effect].scope == "system"
                  else {z: float(t) for z, t in zip(zs, th)})
        out["steps"].append({"effect": effect, "variant": variant, "zones": zs,
                             "parameters": params, "score": sc, "confidence": cf})
        chosen.append(effect)
        C = _columns(sens, effect, variant, c)
        G = np.concatenate([G, C], axis=2)
        nonneg = np.concatenate([nonneg, np.full(C.shape[2], SPECS[effect].sign > 0)])


# --------------------------------------------------------------------------- where


def _season(month: np.ndarray) -> np.ndarray:
    names = np.array(["winter", "winter", "spring", "spring", "spring", "summer", "summer",
                      "summer", "autumn", "autumn", "autumn", "winter"])
    return names[month - 1]


def _slice_table(e: np.ndarray, labels: np.ndarray, zone_wise: bool = False) -> list[dict]:
    """RMS, rows and share of the squared error per label; labels (N,) or (N, nz)."""
    sq = e ** 2
    ok = np.isfinite(sq)
    lab = labels if zone_wise else np.broadcast_to(labels[:, None], e.shape)
    total = sq[ok].sum()
    n_all = ok.sum()
    rows = []
    for value in sorted(set(lab[ok].tolist()), key=str):
        m = ok & (lab == value)
        n = int(m.sum())
        if n == 0:
            continue
        s = float(sq[m].sum())
        rows.append({"slice": str(value), "n": n, "rms": float(np.sqrt(s / n)),
                     "share_of_error": s / total if total else 0.0,
                     "share_of_rows": n / n_all})
    return rows


def where(base: Baseline, data: ModelData, zones: Sequence[str], bz: np.ndarray) -> dict:
    """Residuals of the forecasts and the simulation by slice.

    Returns ``{"forecast": {dimension: [slice rows]}, "simulation": {...}, "carriers":
    [...]}``; ``bz`` is the box-zone incidence (:func:`~.effects.box_zone_matrix`). A slice *carries* the error when its share of the squared error is at least
    1.25 times its share of the rows and at least 10 % of the total.
    """
    local = data.local_times()
    hour = np.asarray(local.hour)
    weekend = np.where(np.asarray(local.day_of_week) >= 5, "weekend", "weekday")
    season = _season(np.asarray(local.month))
    at_min = minimum_airflow_fraction(data.u, bz)
    regime = np.where(at_min >= 0.5, "minimum airflow", "cooling (above minimum)")
    flow = data.u @ bz
    flow_level = np.empty(flow.shape, dtype=object)
    for j in range(flow.shape[1]):
        q = np.quantile(flow[:, j], [1 / 3, 2 / 3])
        flow_level[:, j] = np.where(flow[:, j] <= q[0], "low", np.where(flow[:, j] <= q[1],
                                                                       "mid", "high"))
    sol = np.max(data.v[:, 2:6], axis=1)
    solar = np.where(sol < 10, "night/dark", np.where(sol < 300, "low (<300 W/m2)",
                                                      "high (>=300 W/m2)"))
    ta = data.v[:, 0]
    oat = np.where(ta < 10, "<10 C", np.where(ta < 15, "10-15 C", np.where(ta < 20, "15-20 C",
                                                                          ">=20 C")))
    exc = np.where(data.excitation, "excitation", "normal operation")
    lead_h = np.where(base.lead > 0, (base.lead - 1) // 24 * 6, -1)
    lead_lab = np.array([f"{h}-{h + 6} h" if h >= 0 else "none" for h in lead_h])
    out = {}
    for name, pred in (("forecast", base.pred), ("simulation", base.sim)):
        e = data.y - pred
        zone_lab = np.broadcast_to(np.array(zones)[None, :], e.shape)
        dims = {"zone": _slice_table(e, zone_lab, True), "hour_of_day": _slice_table(e, hour),
                "weekday_weekend": _slice_table(e, weekend), "season": _slice_table(e, season),
                "regime": _slice_table(e, regime, True),
                "airflow_level": _slice_table(e, flow_level, True),
                "solar_level": _slice_table(e, solar), "outdoor_temperature": _slice_table(e, oat),
                "operation": _slice_table(e, exc)}
        if name == "forecast":
            dims["lead"] = _slice_table(e, lead_lab)
        out[name] = dims
    out["carriers"] = [{"residual": name, "dimension": d, **row}
                       for name in ("forecast", "simulation")
                       for d, rows in out[name].items() for row in rows
                       if row["share_of_error"] >= 0.10
                       and row["share_of_error"] >= 1.25 * row["share_of_rows"]]
    return out


# --------------------------------------------------------------------------- orchestration


@dataclass
class Diagnosis:
    """Result of :func:`diagnose` (JSON via :meth:`to_dict`)."""

    where: dict
    ranked: list[Candidate]
    per_zone: dict[str, list[Candidate]]
    split: dict
    gains: str
    seconds: float
    base: Baseline | None = None
    reference: list[dict] = field(default_factory=list)
    #: :func:`forward_selection` (None when not run)
    forward: dict | None = None

    def to_dict(self) -> dict:
        return {
            "where": self.where,
            "ranked_effects": [c.to_dict() for c in self.ranked],
            "per_zone": {z: [c.to_dict() for c in cs] for z, cs in self.per_zone.items()},
            "split": {k: self.split[k] for k in ("train", "validation", "train_starts",
                                                 "validation_starts", "seed")},
            "gains": self.gains,
            "reference": self.reference,
            "profile": None if self.base is None else {
                "zones": list(self.per_zone), "step": str(self.base.profile.step),
                "values": np.round(self.base.profile.values, 4).tolist()},
            "thresholds": {"confidence": CONFIDENCE, "min_score": MIN_SCORE},
            "forward_selection": self.forward,
            "seconds": self.seconds,
        }


@dataclass
class Reference:
    """What the diagnosis of a period known to be free of the faults looked for hands on
    (:func:`load_reference`).

    Attributes
    ----------
    terms : its confident effects (:func:`reference_terms`), added to the base model
    profile : the internal-gains profile its base used [W/m2]; kept fixed, so that a change
        of the building's weekly pattern (reheat on a schedule, an offset sensor) is not
        absorbed by a profile refitted on the data under diagnosis. None: refit as usual.
    gains : the base of the reference diagnosis (``"profile"`` or ``"constant"``); its terms
        were fitted net of that profile and are applied the same way
    """

    terms: list[dict]
    profile: WeeklyProfile | None = None
    gains: str = "profile"


def reference_terms(ranked_effects: Sequence[dict]) -> list[dict]:
    """The confident effects of a reference diagnosis (``diagnosis.json``'s
    ``ranked_effects``) as terms to add to the base model: ``effect``, ``variant``,
    ``parameters`` (zone -> value; the effect's fit in every zone when the entry has it)."""
    out = []
    for c in ranked_effects:
        missing = {"effect", "variant", "parameters", "confident"} - set(c)
        if missing:
            raise DiagnosisError(f"reference effect entry lacks {sorted(missing)}: give the "
                                 "ranked_effects of a diagnosis.json")
        if c["effect"] not in SPECS:
            raise DiagnosisError(f"reference effect {c['effect']!r} is unknown; known: "
                                 f"{list(SPECS)}")
        if c["confident"]:
            # the effect fitted in every zone where the reference has that fit: its weaker
            # zones are part of the known gap too
            params = c.get("parameters_all_zones") or c["parameters"]
            out.append({"effect": c["effect"], "variant": c["variant"],
                        "parameters": dict(params)})
    return out


def load_reference(doc: dict, zones: Sequence[str], timezone: str) -> Reference:
    """A :class:`Reference` from a ``diagnosis.json`` document (its confident effects and,
    when it has one, its base's weekly profile)."""
    if not isinstance(doc, dict) or "ranked_effects" not in doc:
        raise DiagnosisError("the reference has no 'ranked_effects': give a diagnosis.json "
                             "written by zonecast diagnose")
    gains = doc.get("gains", "profile")
    if gains not in ("profile", "constant"):
        raise DiagnosisError(f"the reference diagnosis used gains {gains!r}; a reference must "
                             "itself be diagnosed without a reference ('profile' or "
                             "'constant')")
    prof = None
    wp = doc.get("profile")
    if wp is not None:
        try:
            values = np.asarray(wp["values"], float)
            names = list(wp["zones"])
            step = pd.Timedelta(wp.get("step", "15min"))
        except (KeyError, TypeError, ValueError) as exc:
            raise DiagnosisError(f"the reference's 'profile' is malformed ({exc}): it needs "
                                 "'zones', 'values' and 'step'") from None
        if sorted(names) != sorted(zones):
            raise DiagnosisError(f"the reference's profile zones {names} differ from the "
                                 f"data's {list(zones)}: use a diagnosis of this site")
        nb = int(pd.Timedelta("7D") / step)
        if values.shape != (nb, len(names)):
            raise DiagnosisError(f"the reference's profile values have shape {values.shape}; "
                                 f"expected {(nb, len(names))}")
        values = values[:, [names.index(z) for z in zones]]
        prof = WeeklyProfile(values, np.isfinite(values).astype(int), timezone, step)
    return Reference(reference_terms(doc["ranked_effects"]), prof, gains)


def _apply_reference(resid: np.ndarray, sens: dict, terms: Sequence[dict],
                     zones: Sequence[str]) -> np.ndarray:
    """Residuals of the base model with the reference terms added (superposition: each term
    changes the forecasts by its sensitivity times its parameters)."""
    out = resid.copy()
    for t in terms:
        key = (t["effect"], t["variant"])
        if key not in sens:
            raise DiagnosisError(f"reference term {key} has no sensitivity here: its variant is "
                                 "not one of the library's (effects.py)")
        cols = [list(zones).index(z) for z in t["parameters"]]
        theta = np.array(list(t["parameters"].values()), float)
        out = out - sens[key][:, :, cols] @ theta
    return out


def diagnose(model: BilinearModel, data: ModelData, *, seed: int = 0, gains: str = "profile",
             effects: Sequence[str] | None = None,
             reference: Reference | Sequence[dict] | None = None,
             heating_setpoint: np.ndarray | None = None, forward: bool = True,
             progress: Callable[[str], None] | None = None,
             mass_model: Callable[[int, float], BilinearModel] | None = None) -> Diagnosis:
    """Where, which and how much (module docstring); ``seed`` draws the week split.

    ``reference``: a :class:`Reference` from the diagnosis of a period known to be free of
    the faults looked for (e.g. the commissioning weeks the model was identified on), or
    just its terms (:func:`reference_terms`). Its confident effects are added to the base
    model before scoring, so that what the reference period already showed — the model's
    own structural gap to the building — is not attributed again; with its profile the
    base keeps the reference's internal gains instead of refitting them, so that a change
    with a weekly pattern stays visible. The ranking then names what is *new* in the data.
    Without a reference the ranking is absolute: everything the model lacks, structural
    or not.

    ``heating_setpoint`` (N,) [degC]: the site's scheduled heating set point
    (:meth:`~.site.Thermostat.heating_setpoint`), for the reheat variant ``"schedule"``.

    ``forward``: also run :func:`forward_selection` from the ranking's first effect (which
    other effects remain confident once it is in the model); it does not change the ranking.

    ``mass_model``: ``f(j, scale)`` the model with zone j's furniture area scaled
    (:func:`furniture_rebuilder`), for the thermal-mass term; without it the furniture's
    own nodes are scaled (:func:`scaled_internal_mass`).
    """
    t0 = time.perf_counter()
    zones = list(data.zones)
    if zones != list(model.structure.zones):
        raise DiagnosisError(f"data zones {zones} differ from model zones "
                             f"{list(model.structure.zones)}")
    if reference is not None and not isinstance(reference, Reference):
        reference = Reference(list(reference), None, gains)
    base = baseline(model, data, seed=seed, gains=gains,
                    profile=reference.profile if reference is not None else None,
                    progress=progress)
    if progress:
        progress("residual slices")
    wh = where(base, data, zones, box_zone_matrix(model))
    sens = sensitivities(model, data, base, effects, progress,
                         heating_setpoint=heating_setpoint, mass_model=mass_model)
    resid = data.y - base.pred
    terms = list(reference.terms) if reference is not None else []
    if terms:
        # the terms were fitted net of the reference's own refitted profile (or against
        # constant gains): their sensitivities here are taken the same way
        net = reference.gains == "profile"
        needed = sorted({t["effect"] for t in terms})
        if net == (base.gains == "profile") and not set(needed) - set(effects or SPECS):
            ref_sens = sens
        else:
            ref_sens = sensitivities(model, data, base, needed, progress, net_of_profile=net,
                                     heating_setpoint=heating_setpoint, mass_model=mass_model)
        resid = _apply_reference(resid, ref_sens, terms, zones)
    if progress:
        progress("scoring candidates")
    per = score_candidates(base, data, sens, zones, resid)
    ranked = []
    for effect, by_zone in per.items():
        conf_zones = [z for z, c in by_zone.items() if c.confident]
        if SPECS[effect].scope == "system":
            cand = dataclasses.replace(by_zone[zones[0]])
            if cand.confident:
                cand.parameters_all_zones = dict(cand.parameters)
        elif not conf_zones:
            best = max(by_zone.values(), key=lambda c: c.score)
            cand = dataclasses.replace(best)
        else:
            # one variant for the effect: the one of its best confident zone
            lead = max((by_zone[z] for z in conf_zones), key=lambda c: c.score)
            cols = [zones.index(z) for z in conf_zones]
            cand = _evaluate(base, data, sens[(effect, lead.variant)], resid, effect,
                             lead.variant, cols, zones)
            S, r = _flat(base, sens[(effect, lead.variant)], resid,
                         base.rows_of(base.split["train"]), list(range(len(zones))))
            cand.parameters_all_zones = {
                z: float(t) for z, t in zip(zones, _fit(S, r, SPECS[effect].sign))}
        ranked.append(_heldout(base, data, sens[(effect, cand.variant)], resid, cand, zones))
    ranked = _rank(ranked)
    per_zone = {z: sorted((per[e][z] for e in per), key=lambda c: c.score, reverse=True)
                for z in zones}
    if progress:
        progress("forward selection")
    fwd = forward_selection(base, sens, resid, ranked, zones) if forward else None
    return Diagnosis(wh, ranked, per_zone, base.split, base.gains, time.perf_counter() - t0,
                     base, reference=terms, forward=fwd)
