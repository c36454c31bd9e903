"""Parameter identification, paper section 4-A (sec:param_id).

    γ̂ = argmin Σ_k ‖y(k, γ) − ȳ(k)‖²
    s.t. y, x follow eq:model_dt with f_IG(k) = 0, u = ū, v = v̄, x(0) = x_KF(0),
         γ > 0, 0 ≤ γ_absorp, γ_winSolAbs ≤ 1.

The data are whole excitation weekends (Saturday and Sunday, local time), when occupancy
is low and the experiments decorrelate the zones. x(0) of each weekend comes from a Kalman
filter run over the 24 h before it (the paper's x_KF(0)) with the starting model. The fit
starts from the model's physical values (the priors' means); on request (``n_starts`` > 1)
more starts (the paper's Table 1 where the zones match, and seeded perturbations) look for
other minima, and their spread (cost and end point of each) is reported. The best start's
fit is then repeated once with x(0) re-estimated at its parameters. Standard errors and
correlations come from the Jacobian at the optimum (they assume independent residuals,
which simulation errors are not, so they are optimistic: read them as a ranking of how
well each parameter is determined).
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
import scipy.sparse as sp
from scipy.optimize import least_squares
from zonecast.estimator.constants import SIGMA_AIR_X0, STEPS_PER_DAY
from zonecast.estimator.dataset import ModelData
from zonecast.estimator.evaluate import rms_by_zone
from zonecast.estimator.integrate import (
    ExactStepper,
    _run,
    _run_block,
    chebyshev_coefficients,
    return_rho,
    switched_matrix,
    tight_bound,
)
from zonecast.estimator.kalman import (
    default_initial_covariance,
    default_measurement_noise,
    default_process_noise,
    initial_state_from_measurement,
    run_filter,
)
from zonecast.estimator.model import BilinearModel
from zonecast.estimator.priors import Prior, prior_jacobian, prior_residuals
from zonecast.estimator.rc.parameters import ParameterSet

RESULTS_SCHEMA_VERSION = 1


class IdentificationError(ValueError):
    """The data do not allow identification; the message says what is missing."""


def weekend_spans(data: ModelData, saturdays: Sequence) -> list[tuple[int, int]]:
    """Row ranges [start, stop) of the weekends (Saturday 00:00 to Monday 00:00 local)
    starting on the given Saturdays (dates or strings)."""
    local = data.local_times()
    spans = []
    for sat in saturdays:
        start = pd.Timestamp(pd.Timestamp(sat).date(), tz=data.timezone)
        if start.day_of_week != 5:
            raise IdentificationError(f"{start.date()} is not a Saturday")
        end = start + pd.Timedelta(days=2)
        idx = np.flatnonzero((local >= start) & (local < end))
        if len(idx) == 0:
            raise IdentificationError(f"no telemetry for the weekend of {start.date()}")
        a, b = int(idx[0]), int(idx[-1]) + 1
        if b - a != len(idx) or any(s <= a < e and b > e for s, e in data.segments):
            raise IdentificationError(f"the weekend of {start.date()} has gaps in its telemetry")
        spans.append((a, b))
    return spans


#: identification windows: whole weekends (the paper), or the site's declared experiments
WINDOWS = ("weekend", "experiments")
#: hours kept before and after the experiments of a weekend with ``window="experiments"``
LEAD_IN = pd.Timedelta("2h")
LEAD_OUT = pd.Timedelta("2h")


def identification_spans(data: ModelData, saturdays: Sequence, window: str = "weekend", *,
                         lead_in: pd.Timedelta = LEAD_IN,
                         lead_out: pd.Timedelta = LEAD_OUT) -> list[tuple[int, int]]:
    """Row ranges [start, stop) the identification fits, one per weekend.

    Parameters
    ----------
    data : ModelData
    saturdays : sequence of dates
        Saturdays of the weekends.
    window : {"weekend", "experiments"}
        ``"weekend"``: Saturday 00:00 to Monday 00:00 local (the paper); ``"experiments"``:
        from ``lead_in`` before the first to ``lead_out`` after the last row of the weekend
        that the site's ``experiments`` mark (:attr:`ModelData.excitation`).
    lead_in, lead_out : pandas.Timedelta
        Context kept before and after the experiments.
    """
    if window not in WINDOWS:
        raise IdentificationError(f"window must be one of {WINDOWS}, got {window!r}")
    spans = weekend_spans(data, saturdays)
    if window == "weekend":
        return spans
    step = data.times[1] - data.times[0]
    before, after = int(lead_in / step), int(lead_out / step)
    out = []
    for sat, (a, b) in zip(saturdays, spans):
        rows = a + np.flatnonzero(data.excitation[a:b])
        if len(rows) == 0:
            raise IdentificationError(
                f"the weekend of {pd.Timestamp(sat).date()} has no declared experiment (the "
                "site's experiments list): identify on whole weekends (window='weekend') or "
                "declare the experiment periods")
        out.append((max(a, int(rows[0]) - before), min(b, int(rows[-1]) + 1 + after)))
    return out


def measured_rows(data: ModelData, a: int, b: int) -> slice:
    """Rows of y a simulation of span [a, b) is scored against: x(k+1) is driven by row k,
    so the simulation meets rows a + 1 ... b, but never past the end of the contiguous
    segment holding row a (the next row after a segment is a later week, not the state
    after row b - 1)."""
    stop = next((e for s, e in data.segments if s <= a < e), len(data))
    return slice(a + 1, min(b + 1, stop))


def excitation_saturdays(data: ModelData) -> list[pd.Timestamp]:
    """Saturdays of weekends with excitation experiments (from the site's experiments)."""
    local = data.local_times()[data.excitation]
    sats = sorted({(t - pd.Timedelta(days=(t.day_of_week - 5) % 7)).normalize() for t in local})
    return [s for s in sats if s.day_of_week == 5]


#: steps of telemetry before a weekend that the x(0) filter runs over (24 h; docs)
X0_WINDOW = STEPS_PER_DAY


def kalman_state(model: BilinearModel, data: ModelData, start: int, stop: int,
                 sigma_air: float = SIGMA_AIR_X0, f_ig: np.ndarray | None = None) -> np.ndarray:
    """x_KF at row ``stop``: the Kalman filter (f_IG = 0) over rows [start, stop].

    The filter runs the model with f_IG = 0 through a day of regular operation, whose
    internal gains (~10 W/m2) would heat a room's air by several kelvin per step; the air
    states' process noise must cover that, else the unmeasured wall states absorb the
    missing heat and x(0) is biased. Measured on the virtual building (validation RMS of
    the identified model, fall weekend): sigma_air 0.1 K -> 1.25 degC, 0.3 -> 1.06,
    1 -> 0.54, 3 -> 0.37, 10 -> 0.40 (docs/identification.md).
    """
    air = model.structure.air_states()
    y = data.y[start:stop + 1]
    first = np.flatnonzero(np.isfinite(y).any(axis=1))
    if len(first) == 0:
        raise IdentificationError(f"no zone temperature between rows {start} and {stop}")
    x0 = initial_state_from_measurement(np.where(np.isfinite(y[first[0]]), y[first[0]],
                                                 np.nanmean(y[first[0]])), model.state_zones())
    gains = model.params.c_ig
    # one exact stepper for the window (the kernel's series for its largest airflows): Phi
    # from the series applied to the identity and the forcing's increment from one step of
    # a zero state, ~7x faster than eigendecompositions per distinct airflow
    rows = slice(start, stop + 1)
    u_max = np.max(data.u[rows], axis=0)
    stepper = ExactStepper(model.structure.A(model.params.physical), model._rooms,
                           model._bxu, model.step, u_max, capacity=model.structure.capacity,
                           ret=model._ret, retc=model._retc, switched=model.switched)
    forcing = data.v[rows] @ model.Bv.T + model.reheat_forcing(data.u[rows], data.reheat[rows])
    modes = model.modes(data.u[rows], data.reheat[rows])
    zero = np.zeros(model.n)

    def step(k):
        u = data.u[start + k]
        g = gains if f_ig is None else gains + f_ig[start + k]
        b = forcing[k] + model.B_ig @ g
        mode = None if modes is None else modes[k]
        return (stepper.propagator(u, mode),
                stepper.step(zero, u, b, data.v[start + k, 1], mode))

    res = run_filter(x0, default_initial_covariance(model.n, air), step, y, model.C,
                     default_process_noise(model.n, air, sigma_air=sigma_air),
                     default_measurement_noise(model.n_zones), store_covariance="none")
    return res.x[-1]


def weekend_simulations(model: BilinearModel, data: ModelData, saturdays: Sequence,
                        window: str = "weekend", f_ig: np.ndarray | None = None,
                        x0_gains: np.ndarray | None = None,
                        x0_window: int = X0_WINDOW,
                        x0_offset: np.ndarray | None = None) -> list[dict]:
    """The identification's simulations (f_IG = 0, x(0) = x_KF(0) of ``model``) of the
    weekends starting on ``saturdays``, beside the measurements, for plots. ``f_ig``
    ((N, n_zones) [W/m2] over all rows of ``data``): gains the fit knew (e.g. the fitted
    weekend daytime rise), in the x(0) filter and the simulation, as in Table 2;
    ``x0_gains``, ``x0_window``: the x(0) filter's, as :func:`identify`; ``x0_offset``
    ((n_zones,) [K], ``result.x0_offset()``): the slow states' offsets added to x_KF(0).

    Returns one dict per weekend: ``saturday`` (date string), ``times`` (DatetimeIndex of the
    simulated rows), ``simulated`` and ``measured`` ((N, n_zones) [degC]); the rows and the
    x(0) are those the fit scores (Table 2).
    """
    out = []
    local = data.local_times()
    gains = np.zeros((len(data.times), model.n_zones)) if f_ig is None else np.asarray(f_ig)
    for a, b in identification_spans(data, saturdays, window):
        x0 = kalman_state(model, data, a - x0_window, a,
                          f_ig=gains if x0_gains is None else gains + x0_gains)
        if x0_offset is not None:
            x0 = x0 + slow_state_basis(model) @ np.asarray(x0_offset, float)
        y = model.simulate(x0, data.u[a:b], data.v[a:b], gains[a:b],
                           reheat=data.reheat[a:b]).y
        rows = measured_rows(data, a, b)
        meas = data.y[rows]
        sat = local[a] - pd.Timedelta(days=(local[a].day_of_week - 5) % 7)
        out.append({"saturday": str(sat.date()), "times": data.times[rows],
                    "simulated": y[1:1 + len(meas)], "measured": meas})
    return out


@dataclass
class IdentificationResult:
    """What :func:`identify` found, in the statsmodels manner: ``params``, ``bse``,
    ``cov_params()``, ``summary()`` and the fitted ``model``.

    Attributes
    ----------
    param_names, units : list of str
    params : ndarray
        Identified values, in ``param_names`` order.
    stderr : ndarray
        Standard errors from the Gauss-Newton covariance sigma^2 (J'J)^+ at the optimum
        (also as :attr:`bse`).
    corr : ndarray
        Correlation matrix of the estimates.
    train_rms, validation_rms : dict
        Table 2 rows: zone (and ``mean``) -> RMS [K].
    bounds : list of (float, float)
        Bounds the parameters were fitted within.
    model : BilinearModel or None
        The model with the identified parameters.
    rank, condition : int, float
        Numerical rank and condition number of the residuals' Jacobian at the optimum, its
        columns scaled by the parameters' typical sizes: how many parameter combinations
        the data determine (identifiability).
    priors : dict or None
        The priors of a MAP fit (:mod:`~zonecast.estimator.priors`); None: least squares.
    sigma_e : float or None
        Residual scale [K] of the MAP cost.
    window : str
        ``"weekend"`` or ``"experiments"`` (:func:`identification_spans`).
    spans : list of dict
        The hours fitted (training) and scored (validation): role, local start and end.
    gain_scale : dict or None
        With a weekend gains shape (``identify(gain_shape=)``): zone -> {"value", "se"},
        the shape's fitted scale [-] (not a model parameter; rank and condition include
        it).
    gain_day_scale : dict or None
        With ``identify(day_scale_sd=)``: "zone,date" -> {"value", "se"}, each training
        weekend day's deviation of the zone's scale [-].
    x0_window : int
        Rows of the x(0) filter before each weekend.
    x0_gains : bool
        Whether the x(0) filter knew internal gains on those rows (``identify(x0_gains=)``).
    x0_gains_source : str or None
        What those gains were (``Pipeline.identify`` sets it): ``"meters"`` (the zones'
        metered lights and plug loads, ``x0_meters``), ``"profile"`` (the weekly profile,
        ``x0_profile_days``), None without.
    x0_offsets : dict or None
        With ``identify(x0_offset_sd=)``: zone -> {"value", "se", "prior_sd"}, the fitted
        offset [K] of the zone's slow states at every weekend's start (not a model
        parameter; rank and condition include them; :meth:`x0_offset` as an array).
    """

    param_names: list[str]
    units: list[str]
    params: np.ndarray
    stderr: np.ndarray
    corr: np.ndarray
    train_rms: dict
    validation_rms: dict | None
    starts: list[dict] = field(default_factory=list)
    train_weekends: list[str] = field(default_factory=list)
    validation_weekends: list[str] = field(default_factory=list)
    n_residuals: int = 0
    n_evaluations: int = 0
    seconds: float = 0.0
    seed: int = 0
    bounds: list[tuple[float, float]] = field(default_factory=list)
    model: BilinearModel | None = field(default=None, repr=False)
    rank: int | None = None
    condition: float | None = None
    priors: dict[str, Prior] | None = None
    sigma_e: float | None = None
    window: str = "weekend"
    spans: list[dict] = field(default_factory=list)
    gain_scale: dict | None = None
    gain_day_scale: dict | None = None
    x0_window: int = X0_WINDOW
    x0_gains: bool = False
    x0_gains_source: str | None = None
    x0_offsets: dict | None = None
    #: the weekend-gains mode the fit used (``Pipeline.identify`` resolves ``"auto"``) and
    #: the meters' weekend / working-day daytime rise that chose it (None without meters)
    weekend_gains: str | None = None
    weekend_metered_ratio: float | None = None
    #: film parameter -> factor from the identified films to the films of regular
    #: operation (``Pipeline.identify(operating_films=)``, :func:`~.priors.operating_film_ratios`);
    #: :attr:`model` keeps the identified films (Table 2's weekends), the pipeline's
    #: parameters carry the operating ones. None: not applied (the films everywhere)
    operating_films: dict[str, float] | None = None
    #: ``Pipeline.fit_operating_films``'s test: the zones' precision-weighted mean reheat
    #: leak k at the identified films, its standard error and whether the ratios were
    #: applied (None: not run)
    operating_films_test: dict | None = None

    def x0_offset(self) -> np.ndarray | None:
        """(n_zones,) :attr:`x0_offsets` [K] in zone order, or None."""
        if self.x0_offsets is None:
            return None
        return np.array([v["value"] for v in self.x0_offsets.values()])

    def x0_offsets_line(self) -> str:
        """One line of the fitted x(0) offsets with their prior ('' without them)."""
        if not self.x0_offsets:
            return ""
        sd = next(iter(self.x0_offsets.values()))["prior_sd"]
        return (f"x(0) offsets of the slow states [K], every weekend, prior 0 +- {sd:g}: "
                + ", ".join(f"{z} {v['value']:+.2f} +- {v['se']:.2f}"
                            for z, v in self.x0_offsets.items()))

    @property
    def bse(self) -> np.ndarray:
        """Standard errors of :attr:`params` (statsmodels' name)."""
        return self.stderr

    def cov_params(self) -> np.ndarray:
        """Covariance matrix of the estimates (from :attr:`bse` and :attr:`corr`)."""
        return self.corr * np.outer(self.stderr, self.stderr)

    def at_bounds(self, rtol: float = 1e-6) -> list[str]:
        """Names of the parameters that ended on (within ``rtol`` of the range) a bound."""
        out = []
        for name, v, (lo, hi) in zip(self.param_names, self.params, self.bounds):
            width = (hi - lo) if np.isfinite(hi - lo) else max(abs(v), 1.0)
            if v - lo <= rtol * width or hi - v <= rtol * width:
                out.append(name)
        return out

    def parameters(self) -> dict:
        return {n: {"value": float(v), "unit": u, "stderr": float(s)}
                for n, v, u, s in zip(self.param_names, self.params, self.units, self.stderr)}

    def strongly_correlated(self, threshold: float = 0.9) -> list[tuple[str, str, float]]:
        out = []
        for i in range(len(self.params)):
            for j in range(i + 1, len(self.params)):
                if abs(self.corr[i, j]) >= threshold:
                    out.append((self.param_names[i], self.param_names[j], float(self.corr[i, j])))
        return out

    def summary(self) -> str:
        """A plain-text table: value, unit, standard error, bounds and a flag for every
        parameter at a bound; Table 2; the strongly correlated pairs."""
        bounds = self.bounds or [(float("nan"), float("nan"))] * len(self.params)
        pinned = set(self.at_bounds()) if self.bounds else set()
        weekends = (f"training weekends: {', '.join(self.train_weekends) or '-'}; "
                    f"validation: {', '.join(self.validation_weekends) or '-'}; window "
                    f"{self.window}: " + ", ".join(f"{s['start'][:16]} to {s['end'][:16]}"
                                                   for s in self.spans))
        counts = (f"residuals {self.n_residuals}, evaluations {self.n_evaluations}, "
                  f"{self.seconds:.1f} s, seed {self.seed}")
        lines = ["Identification (paper section 4-A): simulation-error least squares",
                 weekends, counts, "",
                 f"{'parameter':<16}{'value':>12}{'std err':>12}  {'unit':<10}{'bounds':<24}"]
        for name, v, s, u, (lo, hi) in zip(self.param_names, self.params, self.stderr,
                                           self.units, bounds):
            flag = "  AT BOUND" if name in pinned else ""
            prior = self.priors.get(name) if self.priors else None
            if prior is not None:
                flag += (f"  prior {prior.mean:.3g} +- {prior.sd:.3g}"
                         + (" (log-normal)" if prior.log else ""))
            lines.append(f"{name:<16}{v:>12.4g}{s:>12.3g}  {u:<10}[{lo:.4g}, {hi:.4g}]{flag}")
        lines.append("")
        for label, row in (("training RMS [K]", self.train_rms),
                           ("validation RMS [K]", self.validation_rms)):
            if row:
                lines.append(f"{label}: " + ", ".join(f"{k} {v:.3f}" for k, v in row.items()))
        if self.x0_offsets:
            lines.append(self.x0_offsets_line())
        if self.x0_gains_source == "meters":
            lines.append("x(0) filter: the working day before each weekend with each zone's "
                         "metered lights and plug loads above their base as known gains")
        elif self.x0_gains_source == "profile":
            lines.append(f"x(0) filter: {self.x0_window} rows before each weekend with the "
                         "weekly internal-gains profile as known gains")
        if self.rank is not None:
            lines.append(f"Jacobian rank {self.rank} of {len(self.params)}, condition number "
                         f"{self.condition:.3g}")
        if pinned:
            lines.append(f"at a bound (not determined by the data): {', '.join(sorted(pinned))}")
        pairs = self.strongly_correlated()
        if pairs:
            lines.append("strongly correlated (|r| >= 0.9): "
                         + "; ".join(f"{a}/{b} {r:+.2f}" for a, b, r in pairs))
        if self.operating_films:
            lines.append("inside films in regular operation (gains, forecasts, model file): "
                         + ", ".join(f"{k} x{v:.3f}" for k, v in self.operating_films.items())
                         + " of the identified (the experiments' films)")
        test = self.operating_films_test
        if test is not None and not self.operating_films:
            lines.append(f"inside films in regular operation: the identified ones (the reheat "
                         f"leak at them, k {test['k_mean']:+.3f} +- {test['stderr']:.3f}, does "
                         f"not ask for weaker films)")
        return "\n".join(lines)

    def to_dict(self) -> dict:
        return {"schema_version": RESULTS_SCHEMA_VERSION, "parameters": self.parameters(),
                "correlation": {"names": self.param_names, "matrix": np.round(self.corr, 4).tolist()},
                "strongly_correlated": self.strongly_correlated(),
                "table2": {"training": self.train_rms, "validation": self.validation_rms},
                "starts": self.starts, "train_weekends": self.train_weekends,
                "validation_weekends": self.validation_weekends, "n_residuals": self.n_residuals,
                "n_evaluations": self.n_evaluations, "seconds": round(self.seconds, 2),
                "seed": self.seed, "at_bounds": self.at_bounds() if self.bounds else [],
                "jacobian_rank": self.rank, "jacobian_condition": self.condition,
                "prior": None if self.priors is None else
                {n: {"mean": p.mean, "sd": p.sd, "source": p.source, "log": p.log}
                 for n, p in self.priors.items()},
                "map_sigma_e": self.sigma_e, "window": self.window, "spans": self.spans,
                "gain_scale": self.gain_scale, "gain_day_scale": self.gain_day_scale,
                "x0_window": self.x0_window,
                "x0_gains": self.x0_gains, "x0_gains_source": self.x0_gains_source,
                "x0_offsets": self.x0_offsets,
                "weekend_gains": self.weekend_gains,
                "weekend_metered_ratio": self.weekend_metered_ratio,
                "operating_films": self.operating_films,
                "operating_films_test": self.operating_films_test}


class _Problem:
    """Residuals of the simulation error over the spans for a parameter vector.

    Fast path for the many evaluations of a fit: A(θ) is affine in θ (docs/model.md), so
    its sparse values on one fixed pattern are d0 + Σ θ_p d_p; B_v(θ) likewise; one tight
    spectral bound per θ covers every span; the compiled stepping kernel is called
    directly, and the columns of the finite-difference Jacobian run on two threads (the
    kernel releases the GIL).
    """

    def __init__(self, model: BilinearModel, data: ModelData, spans, x0s, threads: int = 2,
                 f_ig: np.ndarray | None = None, shape: np.ndarray | None = None,
                 x0_basis: np.ndarray | None = None, shape_zones: np.ndarray | None = None):
        self.model, self.data, self.spans, self.x0s = model, data, spans, x0s
        # gains shapes [W/m2] whose scales follow c_IG in theta (identify(gain_shape=)): one
        # column per scale, column k on zone shape_zones[k] (default: column z on zone z)
        self.shape = None if shape is None else [np.ascontiguousarray(shape[a:b], dtype=float)
                                                 for a, b in spans]
        self.shape_zones = (None if shape is None else np.arange(shape.shape[1])
                            if shape_zones is None else np.asarray(shape_zones, int))
        # (n, n_zones) directions of the zones' x(0) offsets whose sizes d [K] close theta
        # (identify(x0_offset_sd=)): every span starts at x0s[i] + x0_basis @ d
        self.x0_basis = (None if x0_basis is None
                         else np.ascontiguousarray(x0_basis, dtype=float))
        self.threads = threads
        self.n_evaluations = 0
        st = model.structure
        pattern = abs(st.A0).tocsr()
        for piece in st.A_p:
            pattern = pattern + abs(piece)
        pattern = pattern.tocsr()
        pattern.sum_duplicates()
        pattern.sort_indices()
        self.indptr = pattern.indptr.astype(np.int64)
        self.indices = pattern.indices.astype(np.int64)

        def on_pattern(M):
            M = M.tocsr()
            out = np.zeros(pattern.nnz)
            rows = np.repeat(np.arange(M.shape[0]), np.diff(M.indptr))
            pos = {(int(r), int(c)): i for i, (r, c) in
                   enumerate(zip(np.repeat(np.arange(pattern.shape[0]), np.diff(pattern.indptr)),
                                 pattern.indices))}
            for r, c, val in zip(rows, M.indices, M.data):
                out[pos[(int(r), int(c))]] += val
            return out

        self.d0 = on_pattern(st.A0)
        self.dp = np.array([on_pattern(p) for p in st.A_p])
        self.bv0 = st.Bv0.toarray()
        self.bvp = np.array([p.toarray() for p in st.Bv_p])
        self.n_phys = len(st.A_p)
        self.rooms = np.ascontiguousarray(model._rooms, dtype=np.int64)
        self.bxu = np.ascontiguousarray(model._bxu, dtype=float)
        self.ret = np.ascontiguousarray(model._ret, dtype=np.int64)
        self.retc = np.ascontiguousarray(model._retc, dtype=float)
        self._rho: float | None = None
        self.capacity = st.capacity
        self.u_max = np.max(np.vstack([data.u[a:b] for a, b in spans]), axis=0)
        self.B_ig = model.B_ig
        self.C = model.C
        # the discharge air's known forcing does not depend on theta (room air capacity fixed)
        self.rh = [model.reheat_forcing(data.u[a:b], data.reheat[a:b]) for a, b in spans]
        # the films' convection regimes per span (none: zero columns) and the switched
        # links, whose conductance follows theta (RCStructure.switched)
        self.swi = model._swi
        self.modes = [np.ascontiguousarray(
            model.modes(data.u[a:b], data.reheat[a:b]) if model.n_modes
            else np.zeros((b - a, 0))) for a, b in spans]
        if f_ig is not None:  # known time-varying gains (identify(gains=...)): fixed forcing
            self.rh = [r + f_ig[a:b] @ model.B_ig.T for r, (a, b) in zip(self.rh, spans)]

    def switch_gains(self, phys: np.ndarray) -> np.ndarray:
        """(k, 2) the switched links' extra conductance over each end's capacity [1/s] at
        the physical parameters ``phys``."""
        dg = self.model.structure.switched_conductance(phys)
        return np.ascontiguousarray(np.column_stack([dg / self.capacity[self.swi[:, 0]],
                                                     dg / self.capacity[self.swi[:, 1]]])
                                    if len(dg) else np.zeros((0, 2)))

    def bound(self, theta: np.ndarray) -> float:
        """Spectral bound L [1/s] of A(theta) at the spans' largest airflows (the films'
        stiffest regimes)."""

        phys = np.asarray(theta, float)[:self.n_phys]
        n = len(self.capacity)
        A = sp.csr_matrix((self.d0 + phys @ self.dp, self.indices, self.indptr), shape=(n, n))
        A = A + switched_matrix(n, self.swi, self.switch_gains(phys))
        return tight_bound(A, self.rooms, self.bxu, self.u_max[None, :], self.capacity,
                           ret=self.ret, retc=self.retc)

    def simulate(self, theta: np.ndarray, L: float | None = None) -> list[np.ndarray]:
        """Zone temperatures of every span for parameters ``theta``; ``L`` a spectral bound
        valid for them (default: computed, an eigenvalue problem of ~20 ms)."""
        theta = np.asarray(theta, float)
        nz = self.B_ig.shape[1]
        phys, c_ig = theta[:self.n_phys], theta[self.n_phys:self.n_phys + nz]
        k = self.n_phys + nz
        scale = theta[k:k + len(self.shape_zones)] if self.shape is not None else None
        b_shape = None if self.shape is None else self.B_ig[:, self.shape_zones]
        offsets = self._offsets(theta)
        data_vals = self.d0 + phys @ self.dp
        n = len(self.capacity)
        L = self.bound(theta) if L is None else L
        r = L * self.model.step / 2.0
        if self._rho is None:
            # with return air or one-way couplings: how far the eigenvalues leave the real
            # axis, taken once at the first parameters (the non-symmetric terms do not
            # depend on them; the margin of return_rho covers the conductances' change)
            self._rho = return_rho(
                sp.csr_matrix((data_vals, self.indices, self.indptr), shape=(n, n)),
                self.rooms, self.bxu, self.ret, self.retc, self.u_max, L)
        coef = chebyshev_coefficients(r, rho=self._rho)
        Bv = self.bv0 + np.tensordot(phys, self.bvp, axes=1)
        swg = self.switch_gains(phys)
        out = []
        for i, ((a, b), x0, rh) in enumerate(zip(self.spans, self.x0s, self.rh)):
            u, v = self.data.u[a:b], self.data.v[a:b]
            forcing = v @ Bv.T + c_ig @ self.B_ig.T + rh
            if self.shape is not None:
                forcing = forcing + (self.shape[i] * scale) @ b_shape.T
            if offsets is not None:
                x0 = x0 + self.x0_basis @ offsets
            xs = np.empty((b - a + 1, n))
            _run(self.indptr, self.indices, data_vals, self.rooms, self.bxu, self.ret, self.retc,
                 self.swi, swg, np.ascontiguousarray(x0, float), np.ascontiguousarray(u, float),
                 self.modes[i], np.ascontiguousarray(forcing), np.ascontiguousarray(v[:, 1]),
                 float(self.model.step), float(r), coef, xs)
            out.append(xs[1:] @ self.C.T)
        self.n_evaluations += 1
        return out

    def _offsets(self, theta: np.ndarray) -> np.ndarray | None:
        """(n_zones,) x(0) offsets [K] at the end of ``theta``, or None."""
        if self.x0_basis is None:
            return None
        return np.asarray(theta, float)[len(theta) - self.x0_basis.shape[1]:]

    def offset_columns(self, theta: np.ndarray, L: float) -> np.ndarray:
        """Exact derivatives of the residuals with respect to the x(0) offsets
        (n_residuals, n_zones): the zone temperatures are affine in x(0), so each column
        is the free response (no forcing, the spans' airflows) from its basis direction."""
        m = self.x0_basis.shape[1]
        return self._block_responses(theta, L, self.x0_basis, np.zeros((len(self.capacity), m)),
                                     [np.zeros((b - a, m)) for a, b in self.spans])

    def residuals(self, theta: np.ndarray, L: float | None = None) -> np.ndarray:
        res = []
        for (a, b), y in zip(self.spans, self.simulate(theta, L)):
            # x(k+1) is driven by row k, so y from simulation row k+1 meets measurement row k+1
            meas = self.data.y[measured_rows(self.data, a, b)]
            e = y[:len(meas)] - meas
            res.append(np.where(np.isfinite(e), e, 0.0).ravel())
        return np.concatenate(res)

    def gain_columns(self, theta: np.ndarray, L: float) -> np.ndarray:
        """Exact derivatives of the residuals with respect to c_IG (n_residuals, n_zones),
        and with gains shapes to their scales too (n_residuals, n_zones + n_scales).

        The zone temperatures are affine in c_IG (and in the scales): each column is the
        response of a zero state to the forcing B_IG[:, z] held over every step (times the
        zone's shape for a scale), all columns in one compiled run per span
        (:func:`~zonecast.estimator.integrate._run_block`), on the series of ``theta`` and
        ``L`` as the residuals."""
        n, nz = len(self.capacity), self.B_ig.shape[1]
        m = nz if self.shape is None else nz + len(self.shape_zones)
        weights = []
        for i, (a, b) in enumerate(self.spans):
            w = np.ones((b - a, m))
            if self.shape is not None:
                w[:, nz:] = self.shape[i]
            weights.append(w)
        bcols = (self.B_ig if self.shape is None
                 else np.hstack([self.B_ig, self.B_ig[:, self.shape_zones]]))
        return self._block_responses(theta, L, np.zeros((n, m)), bcols, weights)

    def _block_responses(self, theta: np.ndarray, L: float, x0: np.ndarray,
                         bcols: np.ndarray, weights: list[np.ndarray]) -> np.ndarray:
        """(n_residuals, m) zone-temperature responses of m columns at once, one compiled
        run per span (:func:`~zonecast.estimator.integrate._run_block`): from the initial
        states ``x0`` (n, m) under the forcing ``bcols`` (n, m) times ``weights`` (one
        (rows, m) array per span), no supply air, on the series of ``theta`` and ``L`` as
        the residuals; rows of missing measurements zero, as in :meth:`residuals`."""
        phys = np.asarray(theta, float)[:self.n_phys]
        data_vals = self.d0 + phys @ self.dp
        n, m = x0.shape
        r = L * self.model.step / 2.0
        if self._rho is None:
            self.simulate(theta, L)  # sets rho (the first evaluation always comes first)
        coef = chebyshev_coefficients(r, rho=self._rho)
        bcols = np.ascontiguousarray(bcols, dtype=float)
        swg = self.switch_gains(phys)
        out = []
        for (a, b), w, modes in zip(self.spans, weights, self.modes):
            u = np.ascontiguousarray(self.data.u[a:b], dtype=float)
            xs = np.empty((b - a + 1, n, m))
            _run_block(self.indptr, self.indices, data_vals, self.rooms, self.bxu, self.ret,
                       self.retc, self.swi, swg, np.array(x0, dtype=float), u, modes, bcols,
                       np.ascontiguousarray(w, dtype=float), np.zeros(b - a),
                       float(self.model.step), float(r), coef, xs)
            dy = np.einsum("oi,kiz->koz", self.C, xs[1:])
            meas = self.data.y[measured_rows(self.data, a, b)]
            dy = np.where(np.isfinite(meas)[:, :, None], dy[:len(meas)], 0.0)
            out.append(dy.reshape(-1, m))
        return np.vstack(out)

    def jacobian(self, theta: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                 rel_step: float = 1e-4) -> np.ndarray:
        """Forward differences inside the bounds for the physical parameters, exact columns
        for c_IG (:meth:`gain_columns`), computed on ``threads`` threads.

        All columns use the spectral bound of ``theta`` with a 2 % margin: a relative step
        of 1e-4 moves the extreme eigenvalue far less, and one series for the base point
        and its neighbours keeps the differences free of series-truncation noise (and
        saves an eigenvalue problem per column)."""
        theta = np.asarray(theta, float)
        L = 1.02 * self.bound(theta)
        f0 = self.residuals(theta, L)
        steps = rel_step * np.maximum(np.abs(theta), 1.0)
        steps = np.where(theta + steps > hi, -steps, steps)   # step backwards at the upper bound

        def column(i):
            t = theta.copy()
            t[i] += steps[i]
            return (self.residuals(t, L) - f0) / steps[i]

        with ThreadPoolExecutor(max_workers=self.threads) as pool:
            gains = pool.submit(self.gain_columns, theta, L)
            offsets = (None if self.x0_basis is None
                       else pool.submit(self.offset_columns, theta, L))
            cols = list(pool.map(column, range(self.n_phys)))
            extra = [] if offsets is None else [offsets.result()]
            return np.column_stack(cols + [gains.result()] + extra)


def slow_state_basis(model: BilinearModel) -> np.ndarray:
    """(n, n_zones) 1 on every state of a zone's rooms but the air (walls' layers, slabs,
    furniture; :meth:`~.model.BilinearModel.state_zones`): the directions of the x(0)
    offsets of ``identify(x0_offset_sd=)``."""
    zones = model.state_zones()
    slow = np.ones(model.n, bool)
    slow[model.structure.air_states()] = False
    return np.stack([(zones == j) & slow for j in range(model.n_zones)], axis=1).astype(float)


def _day_shapes(data: ModelData, shape: np.ndarray, spans
                ) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """``shape`` (N, n_zones) extended by one column per (weekend day of ``spans``, zone):
    the zone's shape on that local day's rows, zero elsewhere. Returns the columns
    (N, n_zones + n_days n_zones), the zone of each column and the day columns' names
    ``ds_IG[zone,YYYY-MM-DD]``."""
    local = data.local_times()
    dates = np.asarray(local.date)
    weekend = np.asarray(local.day_of_week >= 5)
    days = sorted({dates[r] for a, b in spans for r in range(a, b) if weekend[r]})
    cols, zones, names = [shape], list(range(shape.shape[1])), []
    for d in days:
        on = (dates == d)[:, None]
        cols.append(shape * on)
        zones += list(range(shape.shape[1]))
        names += [f"ds_IG[{z},{d.isoformat()}]" for z in data.zones]
    return np.hstack(cols), np.asarray(zones, int), names


def _per_row_and_zone(arr, data: ModelData, name: str) -> np.ndarray | None:
    """``arr`` as an (N, n_zones) float array with NaN as 0, or None; a clear error for
    another shape."""
    if arr is None:
        return None
    arr = np.nan_to_num(np.asarray(arr, float))
    if arr.shape != (len(data.times), len(data.zones)):
        raise IdentificationError(f"{name} has shape {arr.shape}; give one value per row and "
                                  f"zone {(len(data.times), len(data.zones))}")
    return arr


def _starts(params: ParameterSet, n_starts: int, rng: np.random.Generator) -> list[np.ndarray]:
    lo, hi = np.array(params.bounds).T
    base = params.start_params
    starts = [base]
    try:
        paper = ParameterSet.paper_table1()
        if sorted(paper.zones) == sorted(params.zones):
            starts.append(np.array([paper[n] for n in params.param_names]))
    except (KeyError, ValueError):
        pass
    while len(starts) < n_starts:
        s = base.copy()
        for i, (l, h) in enumerate(zip(lo, hi)):
            if l >= 0 and h <= 1:                       # absorption coefficients
                s[i] = rng.uniform(0.05, 0.95)
            elif l > 0:                                 # film coefficients, U_win
                s[i] = base[i] * np.exp(rng.normal(0.0, 0.5))
            else:                                       # background gains
                s[i] = base[i] + rng.normal(0.0, 5.0)
        starts.append(np.clip(s, lo + 1e-9, hi - 1e-9))
    return starts[:n_starts]


def _fit_rms(problem: _Problem, theta: np.ndarray, zones) -> dict:
    sims = problem.simulate(theta)
    preds, meas = [], []
    for (a, b), y in zip(problem.spans, sims):
        mm = problem.data.y[measured_rows(problem.data, a, b)]
        preds.append(y[:len(mm)])
        meas.append(mm)
    return rms_by_zone(np.vstack(preds), np.vstack(meas), zones)


def identify(model: BilinearModel, data: ModelData, train: Sequence, validation: Sequence = (),
             n_starts: int = 1, seed: int = 0, max_nfev: int = 60,
             progress=lambda msg: None, priors: Mapping[str, Prior] | None = None,
             sigma_e: float = 0.3, window: str = "weekend", f_ig: np.ndarray | None = None,
             start: np.ndarray | None = None, agree_rtol: float = 1e-3,
             gain_shape: np.ndarray | None = None,
             shape_prior: tuple[float, float] = (1.0, 1.0),
             x0_gains: np.ndarray | None = None,
             x0_window: int | None = None,
             x0_offset_sd: float | None = None,
             day_scale_sd: float | None = None) -> IdentificationResult:
    """Identify the parameters of ``model`` (paper section 4-A).

    Parameters
    ----------
    model : the model with its starting parameters
    data : telemetry in model terms (:func:`zonecast.estimator.dataset.model_data`)
    train, validation : Saturdays of the training and validation weekends
    n_starts : the most starting points tried (the best fit is kept); the starts stop
        early once the two best fits so far reach the same cost within ``agree_rtol``
        (two starts that meet are taken as the optimum; a third would only confirm it).
        Default 1, the model's own (physical, the priors' means) starting values: on the
        family's training members more starts changed Table 2 on one member of 12, for
        the worse on its validation weekend (docs/identification.md, 2026-11-25)
    seed : seeds the perturbed starts
    max_nfev : function evaluations per start and round
    priors : mapping, optional
        Parameter name -> :class:`~zonecast.estimator.priors.Prior` for a
        maximum-a-posteriori fit (:mod:`zonecast.estimator.priors`); default none, the
        paper's least squares.
    sigma_e : float
        Residual scale [K] the data are trusted to in the MAP cost.
    window : {"weekend", "experiments"}
        What of each weekend is fitted (:func:`identification_spans`); the result says
        which hours (``spans``).
    f_ig : ndarray (N, n_zones), optional
        Internal gains [W/m2] known at every row of ``data``, added to c_IG in the fit,
        the x(0) filter and Table 2 (the paper: none, f_IG = 0 on weekends; used by
        :meth:`~zonecast.estimator.pipeline.Pipeline.identify` with
        ``weekend_gains=True`` for buildings occupied at weekends).
    start : ndarray, optional
        The first starting point (instead of the start values); with ``n_starts`` > 1 the
        drawn ones follow it.
    agree_rtol : float
        Relative cost difference [-] under which two starts count as the same optimum;
        0 runs every start.
    gain_shape : ndarray (N, n_zones), optional
        A per-zone shape of the weekends' internal gains [W/m2] (e.g. the weekly profile
        of the weeks without experiments) whose per-zone scale s_z [-] is estimated with
        the parameters: f_IG = c_IG + s_z shape_z(t) on the fitted rows, the x(0) filter
        and Table 2 (``result.gain_scale``). The scales are the fit's, not the model's:
        forecasts use the model's 13 parameters and their own gains.
    shape_prior : (float, float)
        Mean and standard deviation [-] of each scale's Gaussian prior in a MAP fit
        (1 ± 1: the shape is the expected gains, a weekend's own may be none or twice
        them); bounds [0, 5].
    x0_gains : ndarray (N, n_zones), optional
        Internal gains [W/m2] the x(0) filter knows on the rows before each weekend (e.g.
        the weekly profile on the working days), added to the fit's own known gains in
        the filter only: the simulated weekends keep theirs.
    x0_window : int, optional
        Rows of the x(0) filter before each weekend (default :data:`X0_WINDOW`, a day).
    x0_offset_sd : float, optional
        Standard deviation [K] of the prior (mean 0) of one offset per zone of the slow
        states' x(0), estimated with the parameters (an option, default off;
        docs/identification.md "The x(0) filter's bias in the slow states"): every weekend
        starts at x_KF(0) plus d_z on each state of zone z but the room air (walls' layers,
        slabs, furniture; :func:`slow_state_basis`). The x(0) filter runs through a working
        day with f_IG = 0 and leaves those states biased the same way before every weekend
        (colder: the day's gains are missing), so the offset is shared by the weekends:
        fitted on the training ones, applied to the validation ones in Table 2
        (``result.x0_offsets``; :func:`weekend_simulations` ``x0_offset``). The forecasts
        do not use this filter. Needs ``priors``.
    day_scale_sd : float, optional
        With ``gain_shape``: each weekend day of the training weekends also gets its own
        deviation d_{day,z} of each zone's scale, prior N(0, ``day_scale_sd``) (bounds
        -5..5), so f_IG = c_IG + (s_z + d_{day,z}) shape_z(t) on that day's rows: people
        who come in at weekends do so on some days and not others, and one scale for all
        days leaves each day's difference to the parameters. Validation weekends and the
        x(0) filter's rows outside the training days take s_z alone
        (``result.gain_day_scale``). Needs ``priors``.
    """
    t0 = time.perf_counter()
    rng = np.random.default_rng([seed, 11])
    train_spans = identification_spans(data, train, window)
    val_spans = identification_spans(data, validation, window) if validation else []
    x0_window = X0_WINDOW if x0_window is None else int(x0_window)
    x0_gains = _per_row_and_zone(x0_gains, data, "x0_gains")
    for a, _ in train_spans + val_spans:
        if not any(s <= a - x0_window and a <= e for s, e in data.segments):
            raise IdentificationError(
                f"the weekend starting {data.local_times()[a].date()} needs the "
                f"{x0_window * 15 // 60} h before it in the same contiguous telemetry (the "
                "Kalman filter estimates x(0) over them)")
    lo, hi = (np.array(b) for b in zip(*model.params.bounds))
    scale = np.maximum(np.abs(model.params.start_params), 1.0)
    n_model = len(lo)
    names = list(model.params.param_names)
    if gain_shape is not None:
        gain_shape = _per_row_and_zone(gain_shape, data, "gain_shape")
        nz = len(data.zones)
        lo, hi = np.r_[lo, np.zeros(nz)], np.r_[hi, np.full(nz, 5.0)]
        scale = np.r_[scale, np.ones(nz)]
        names = names + [f"s_IG[{z}]" for z in data.zones]
        if priors is not None:
            priors = {**priors, **{f"s_IG[{z}]": Prior(*shape_prior, "the gains shape's scale")
                                   for z in data.zones}}
    shape_zones = None
    day_names: list[str] = []
    if day_scale_sd is not None:
        if gain_shape is None or priors is None:
            raise IdentificationError("day_scale_sd needs a gains shape (gain_shape) and a MAP "
                                      "fit (priors): without a prior the days' scales trade "
                                      "with the parameters")
        if not day_scale_sd > 0:
            raise IdentificationError(f"day_scale_sd must be > 0, got {day_scale_sd}")
        gain_shape, shape_zones, day_names = _day_shapes(data, gain_shape, train_spans)
        k = len(day_names)
        lo, hi = np.r_[lo, np.full(k, -5.0)], np.r_[hi, np.full(k, 5.0)]
        scale = np.r_[scale, np.ones(k)]
        names = names + day_names
        priors = {**priors, **{n: Prior(0.0, day_scale_sd, "a day's deviation of the gains "
                                                           "shape's scale") for n in day_names}}

    n_shape = len(names) - n_model  # the gains shape's scales after the model's parameters
    x0_basis = None
    if x0_offset_sd is not None:
        if priors is None:
            raise IdentificationError("x0_offset_sd needs a MAP fit (priors): without a prior "
                                      "the offsets of the slow states are not determined")
        if not x0_offset_sd > 0:
            raise IdentificationError(f"x0_offset_sd must be > 0 K, got {x0_offset_sd}")
        x0_basis = slow_state_basis(model)
        m = x0_basis.shape[1]
        lo = np.r_[lo, np.full(m, -4.0 * x0_offset_sd)]
        hi = np.r_[hi, np.full(m, 4.0 * x0_offset_sd)]
        scale = np.r_[scale, np.full(m, x0_offset_sd)]
        off_names = [f"dx0[{z}]" for z in data.zones]
        names = names + off_names
        priors = {**priors, **{n: Prior(0.0, x0_offset_sd, "the x(0) filter's uncertainty")
                               for n in off_names}}
    n_fit = n_model + n_shape  # parameters without the x(0) offsets

    def known_gains(theta):
        """f_IG known at every row for parameters ``theta``: the given gains and the shape
        times its scales."""
        if gain_shape is None:
            return f_ig
        g = gain_shape * np.asarray(theta, float)[n_model:n_fit]
        if shape_zones is not None:  # per-day columns add to their zones
            g = g @ np.eye(len(data.zones))[shape_zones]
        return g if f_ig is None else f_ig + g

    def x0s(m, spans, theta):
        # one Kalman filter per span, on two threads (the dense products release the GIL)
        g = known_gains(theta)
        if x0_gains is not None:
            g = x0_gains if g is None else g + x0_gains
        with ThreadPoolExecutor(max_workers=2) as pool:
            return list(pool.map(lambda sp: kalman_state(m, data, sp[0] - x0_window, sp[0],
                                                         f_ig=g), spans))

    def fit(problem, theta):
        if priors is None:
            fun, jac = problem.residuals, (lambda t, p=problem: p.jacobian(t, lo, hi))
        else:  # MAP: the prior's rows appended to the simulation residuals
            def fun(t, p=problem):
                return np.concatenate([p.residuals(t), prior_residuals(t, priors, names,
                                                                       sigma_e)])

            def jac(t, p=problem):
                return np.vstack([p.jacobian(t, lo, hi),
                                  prior_jacobian(priors, names, sigma_e, t)])
        return least_squares(fun, theta, bounds=(lo, hi), x_scale=scale, method="trf",
                             max_nfev=max_nfev, jac=jac, ftol=1e-6, xtol=1e-6, gtol=1e-8)

    best = None
    starts_report = []
    progress("x(0) of the training weekends")
    # round 1, every start: x_KF(0) of the start model
    thetas = _starts(model.params, n_starts, rng)
    if start is not None:  # the given point first, the drawn ones after it
        thetas = [np.asarray(start, float)] + thetas[1:]
    if gain_shape is not None:  # a start holds the model's values and at most the base scales
        thetas = [t[:n_model + len(data.zones)] for t in thetas]
        thetas = [t if len(t) >= n_fit else
                  np.r_[t, np.full(n_shape - len(day_names) - max(len(t) - n_model, 0),
                                   shape_prior[0]), np.zeros(len(day_names))]
                  for t in thetas]
    thetas = [t if len(t) == len(lo) else np.r_[t, np.zeros(len(lo) - len(t))] for t in thetas]
    thetas = [np.clip(t, lo, hi) for t in thetas]
    first = _Problem(model, data, train_spans, x0s(model, train_spans, thetas[0]), f_ig=f_ig,
                     shape=gain_shape, x0_basis=x0_basis, shape_zones=shape_zones)
    for i, theta0 in enumerate(thetas):
        progress(f"start {i + 1}/{len(thetas)}")
        sol = fit(first, theta0)
        cost = float(np.sum(sol.fun ** 2))
        starts_report.append({"start": theta0.tolist(), "end": sol.x.tolist(), "cost": cost,
                              "status": int(sol.status), "nfev": int(sol.nfev)})
        if best is None or cost < best[0]:
            best = (cost, sol)
        costs = sorted(s["cost"] for s in starts_report)
        if (len(costs) >= 2 and i + 1 < len(thetas)
                and costs[1] - costs[0] <= agree_rtol * max(costs[0], 1e-300)):
            progress(f"starts {len(costs)} agree within {agree_rtol:g} of the cost: the "
                     f"remaining {len(thetas) - i - 1} skipped")
            break
    # round 2, the best start only: x(0) re-estimated with its parameters, then refitted
    progress("x(0) at the best start's parameters, refit")
    problem = _Problem(model, data, train_spans,
                       x0s(model.with_params(best[1].x[:n_model]), train_spans, best[1].x),
                       f_ig=f_ig, shape=gain_shape, x0_basis=x0_basis, shape_zones=shape_zones)
    sol = fit(problem, best[1].x)
    theta = sol.x
    cost = float(np.sum(sol.fun ** 2))
    J = sol.jac
    dof = max(len(sol.fun) - len(theta), 1)
    sigma2 = cost / dof
    cov = sigma2 * np.linalg.pinv(J.T @ J)
    se = np.sqrt(np.clip(np.diag(cov), 0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(se, se)
    corr = np.nan_to_num(corr)
    singular = np.linalg.svd(J * scale[None, :], compute_uv=False)
    tol = singular.max() * max(J.shape) * np.finfo(float).eps if len(singular) else 0.0
    rank = int(np.sum(singular > tol))
    condition = float(singular.max() / singular.min()) if singular.min() > 0 else float("inf")
    fitted = model.with_params(theta[:n_model])
    # Table 2 as the paper defines it: simulations from x(0) = x_KF(0) of the identified
    # model, the same for training and validation weekends (the last refit started from
    # x(0) of the parameters before it)
    # with x(0) offsets (x0_offset_sd): every weekend, training and validation, starts at
    # x_KF(0) plus the zones' fitted offsets of the slow states (the filter's bias)
    spans_x0 = x0s(fitted, train_spans + val_spans, theta)
    train_rms = _fit_rms(_Problem(model, data, train_spans, spans_x0[:len(train_spans)],
                                  f_ig=f_ig, shape=gain_shape, x0_basis=x0_basis,
                                  shape_zones=shape_zones), theta, data.zones)
    val_rms = None
    if val_spans:
        vp = _Problem(model, data, val_spans, spans_x0[len(train_spans):], f_ig=f_ig,
                      shape=gain_shape, x0_basis=x0_basis, shape_zones=shape_zones)
        val_rms = _fit_rms(vp, theta, data.zones)
    x0_offsets = None
    if x0_basis is not None:
        x0_offsets = {z: {"value": float(theta[n_fit + j]), "se": float(se[n_fit + j]),
                          "prior_sd": float(x0_offset_sd)} for j, z in enumerate(data.zones)}
        theta, se, corr = theta[:n_fit], se[:n_fit], corr[:n_fit, :n_fit]
        lo, hi, names = lo[:n_fit], hi[:n_fit], names[:n_fit]
        priors = {n: priors[n] for n in names}
    gain_scale = gain_day_scale = None
    if gain_shape is not None:
        gain_scale = {z: {"value": float(theta[n_model + i]), "se": float(se[n_model + i])}
                      for i, z in enumerate(data.zones)}
    if day_names:
        k0 = n_model + len(data.zones)
        gain_day_scale = {n[len("ds_IG["):-1]: {"value": float(theta[k0 + i]),
                                                "se": float(se[k0 + i])}
                          for i, n in enumerate(day_names)}
    if gain_shape is not None:
        theta, se, corr = theta[:n_model], se[:n_model], corr[:n_model, :n_model]
        lo, hi = lo[:n_model], hi[:n_model]
        priors = None if priors is None else {n: priors[n] for n in names[:n_model]}
    local = data.local_times()
    step = data.times[1] - data.times[0]
    used = [{"role": role, "start": local[a].isoformat(), "end": (local[b - 1] + step).isoformat()}
            for role, spans in (("training", train_spans), ("validation", val_spans))
            for a, b in spans]
    return IdentificationResult(
        list(model.params.param_names), list(model.params.units), theta, se, corr, train_rms,
        val_rms, starts_report, [str(local[a].date()) for a, _ in train_spans],
        [str(local[a].date()) for a, _ in val_spans], len(sol.fun),
        sum(s["nfev"] for s in starts_report) + int(sol.nfev), time.perf_counter() - t0, seed,
        bounds=[(float(lo_), float(hi_)) for lo_, hi_ in zip(lo, hi)], model=fitted, rank=rank,
        condition=condition, priors=dict(priors) if priors is not None else None,
        sigma_e=sigma_e if priors is not None else None, window=window, spans=used,
        gain_scale=gain_scale, x0_window=x0_window, x0_gains=x0_gains is not None,
        x0_offsets=x0_offsets, gain_day_scale=gain_day_scale)
