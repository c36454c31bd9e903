"""Prior knowledge of the 13 parameters, for maximum-a-posteriori identification.

A parameter the excitation data do not determine ends on a bound in a plain least-squares
fit (the optimiser bends it to absorb structure the model lacks: U_win 0.001 W/m²K for real
glazing of 2-6 W/m²K). A Gaussian prior on each parameter, centred on a nominal value from
the building's EnergyPlus description where it holds one (window U-factor and SHGC, the
exterior walls' solar absorptance) and on
handbook values otherwise, keeps such parameters where physics puts them and leaves the
well-determined ones to the data.

MAP cost (paper section 4-A's simulation-error least squares plus the prior)::

    sum_k ||y_sim(k) - y(k)||^2 / sigma_e^2 + sum_p ((theta_p - mu_p) / sigma_p)^2

with, for the positive coefficients held by log-normal priors (the films and U_win with
``building_priors(positive="log")``, the identification's default since 2026-12-06), the
term ``(ln(theta_p / mu_p) / (sigma_p / mu_p))^2`` instead: same median, same relative
spread, but a film near zero as improbable as one many times its nominal value.

solved as least squares with the prior rows ``sigma_e (theta_p - mu_p) / sigma_p`` appended to
the residuals (:func:`prior_residuals`). ``sigma_e`` [K] is the residual scale the data are
trusted to; simulation residuals are autocorrelated, so it is a choice, made on the training
members of a building family (docs/identification.md).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from zonecast.estimator import outside_films
from zonecast.estimator.films import (
    CONVECTIVE_FILMS,
    NATURAL_ALGORITHMS,
    TARP_FILMS,
    convective_films,
)
from zonecast.estimator.idf import Building
from zonecast.estimator.rc.network import outer_absorptance
from zonecast.estimator.rc.parameters import ParameterSet

__all__ = ["CONVECTIVE_FILMS", "OPERATING_FILMS", "TARP_FILMS", "Prior", "building_priors",
           "convective_films", "operating_film_ratios",
           "prior_jacobian", "prior_residuals", "roof_film_prior"]


@dataclass(frozen=True)
class Prior:
    """A Gaussian prior on one parameter.

    Attributes
    ----------
    mean : float
        Nominal value [the parameter's unit].
    sd : float
        Standard deviation [the parameter's unit].
    source : str
        Where the nominal value comes from.
    """

    mean: float
    sd: float
    source: str
    log: bool = False

    def __post_init__(self):
        if not np.isfinite(self.mean) or not self.sd > 0:
            raise ValueError(f"a prior needs a finite mean and a positive sd, got "
                             f"{self.mean} +- {self.sd}")
        if self.log and not self.mean > 0:
            raise ValueError(f"a log-normal prior needs a positive median, got {self.mean}")

    @property
    def log_sd(self) -> float:
        """Standard deviation [-] of ln(theta) for a log-normal prior: the relative spread
        sd / mean, so that near its median the prior weighs deviations as the Gaussian of the
        same mean and sd does."""
        return self.sd / self.mean


#: handbook priors of the shared parameters: (mean, sd, source); the means are the
#: ParameterSet start values, the sds their plausible spread
_HANDBOOK = {
    "gamma_EW": (25.0, 12.0, "ASHRAE Fundamentals ch. 26 outside film 15-35 W/m2K"),
    "gamma_IW": (8.3, 4.0, "ASHRAE Fundamentals ch. 26 vertical inside film"),
    "gamma_floor": (6.1, 3.0, "ASHRAE Fundamentals ch. 26 horizontal, heat flow down"),
    "gamma_ceil": (9.3, 4.5, "ASHRAE Fundamentals ch. 26 horizontal, heat flow up"),
    "gamma_absorp": (0.6, 0.2, "solar absorptance of opaque facades 0.4-0.8"),
    "gamma_winSolAbs": (0.4, 0.2, "SHGC of common glazing 0.25-0.7"),
    "U_win": (2.8, 1.4, "double glazing in an aluminium frame (ASHRAE ch. 15)"),
}
#: Inside films in regular operation relative to the films identified on the excitation
#: experiments [-], for the natural-convection algorithms (:data:`NATURAL_ALGORITHMS`):
#: EnergyPlus's TARP films of 69 rooms of five training members of the seed-0 family
#: (office6, f0-03, f0-13, f0-17, f0-18) are 1.30x (floors), 1.14x (walls) and 1.04x
#: (ceilings) as large in the experiments as in working hours, because the experiments'
#: widened thermostat and forced airflows hold the faces 1.3-2.8 K from the air against
#: -0.4 to +1.9 K in operation and a natural-convection film grows as |dT|^(1/3)
#: (benchmarks/bench_convection_regimes.py --by experiments; docs/identification.md
#: "Operating films"). gamma_IW's ratio is the walls' (internal mass included). Not
#: general: the DOE small office's packaged units give walls 0.80x, floors about 1x.
OPERATING_FILMS = {"gamma_floor": 1 / 1.30, "gamma_IW": 1 / 1.14, "gamma_ceil": 1 / 1.04}
#: ``Pipeline.identify(operating_films=)``: the ratios above for a natural-convection
#: algorithm (``"natural"``) or the identified films everywhere (``"none"``)
OPERATING_FILM_MODES = ("natural", "none")


def operating_film_ratios(building: Building | None, mode: str = "natural"
                          ) -> dict[str, float]:
    """Film parameter -> factor [-] from the identified (experiment) films to the films
    of regular operation: :data:`OPERATING_FILMS` when ``mode`` is ``"natural"`` and the
    building's declared inside algorithm is a natural-convection one
    (:data:`NATURAL_ALGORITHMS`: TARP, EnergyPlus's default, and the adaptive and ASTM
    C1340 algorithms), empty otherwise (``Simple``'s films are constants, ``CeilingDiffuser``'s
    follow the airflow; no building: nothing known)."""
    if mode not in OPERATING_FILM_MODES:
        raise ValueError(f"operating_films={mode!r}: use one of "
                         f"{', '.join(map(repr, OPERATING_FILM_MODES))}")
    algo = getattr(building, "inside_convection", None)
    if mode == "none" or algo is None or algo.lower() not in NATURAL_ALGORITHMS:
        return {}
    return dict(OPERATING_FILMS)


#: c_IG: background gains, weakly held near idle equipment and lighting
_C_IG = (5.0, 10.0, "idle equipment and lighting 2-10 W/m2, weak")


#: parameters that are positive coefficients (films, glazing U) [W/(m2 K)]: their uncertainty
#: is relative, so ``building_priors(positive="log")`` puts their priors on ln(theta)
POSITIVE = ("gamma_EW", "gamma_IW", "gamma_floor", "gamma_ceil", "U_win", "gamma_roof")


def roof_film_prior(building: Building | None) -> tuple[float, float, str]:
    """(mean, sd, source) of the roofs' own outside film gamma_roof [W/(m2 K)]
    (``ModelOptions.roof_exterior="own"``): the area-weighted climate film of the
    building's roofs open to the outdoors (:func:`~zonecast.estimator.outside_films.climate_films`:
    the mean over the weather file's hours of the outside correlation the building names,
    with the wind at each roof's height), with gamma_EW's handbook relative spread
    (12 / 25); without a weather file or roofs, gamma_EW's handbook prior."""
    mean, sd, source = _HANDBOOK["gamma_EW"]
    if building is None:
        return mean, sd, source + " (no building: the handbook's)"
    roofs = {n: s.area for n, s in building.surfaces.items()
             if s.boundary == "Outdoors" and s.surface_type == "Roof" and s.area > 0}
    if not roofs:
        return mean, sd, source + " (no roof open to the outdoors)"
    try:
        films = outside_films.climate_films(building, list(roofs))
    except (ValueError, OSError) as err:
        return mean, sd, f"{source} (no climate film: {err})"
    h = _area_mean([(films[n], a) for n, a in roofs.items()])
    return h, h * sd / mean, (f"roofs' climate film, {building.outside_convection} over the "
                              "weather file's hours, with γ_EW's relative spread")
#: ways to hold the positive coefficients: Gaussian on theta, or on ln(theta)
POSITIVE_PRIORS = ("normal", "log")


def building_priors(params: ParameterSet, building: Building | None = None, *,
                    window_sd: float = 0.25, convective: bool | str = False,
                    positive: str = "normal") -> dict[str, Prior]:
    """Priors of every parameter of ``params``.

    Parameters
    ----------
    params : ParameterSet
        The parameters (names) to give priors.
    building : Building, optional
        When its windows carry a U-factor and SHGC (simple glazing systems), the
        area-weighted means are the nominal U_win and gamma_winSolAbs; the area-weighted
        solar absorptance of its exterior walls' outer layers (EnergyPlus's 0.7 where a
        material gives none) is gamma_absorp's (since 2026-12-06; the handbook's 0.6
        without walls), with the handbook's spread.
    window_sd : float
        Relative standard deviation [-] of the window priors taken from the building.
    convective : bool or "idf"
        The inside films are convection alone (:data:`CONVECTIVE_FILMS`), as in a model
        whose faces exchange long-wave radiation with each other; ``"idf"``: convection
        alone, of the building's declared inside algorithm (:func:`convective_films`);
        otherwise the handbook's combined films.
    positive : {"normal", "log"}
        ``"log"``: the priors of the positive coefficients (:data:`POSITIVE`) are log-normal,
        median the nominal value and ln-spread its relative sd (:attr:`Prior.log_sd`), so a
        film or U-factor near zero is as improbable as one many times its nominal value; a
        Gaussian of 25 +- 12 W/m2K lets an exterior film fall to its 0.001 bound at the cost
        of two standard deviations.

    Returns
    -------
    dict
        Parameter name -> :class:`Prior`.
    """
    out = {}
    for name, (mean, sd, source) in _HANDBOOK.items():
        out[name] = Prior(mean, sd, source)
    if "gamma_roof" in params.param_names:
        out["gamma_roof"] = Prior(*roof_film_prior(building))
    if convective == "idf":
        out.update({name: Prior(*v) for name, v in convective_films(building).items()})
    elif convective:
        out.update({name: Prior(*v) for name, v in CONVECTIVE_FILMS.items()})
    if building is not None:
        wins = [w for w in building.windows.values() if w.area > 0]
        u = _area_mean([(w.u_value, w.area) for w in wins if w.u_value is not None])
        if u is not None:
            out["U_win"] = Prior(u, window_sd * u, "area-weighted window U-factor of the IDF")
        # gamma_absorp scales the walls' sun: their own absorptance is its nominal value
        a = _area_mean([(outer_absorptance(building.constructions[sf.construction]), sf.area)
                        for sf in building.surfaces.values()
                        if sf.boundary == "Outdoors" and sf.surface_type.lower() == "wall"
                        and sf.construction in building.constructions
                        and not building.constructions[sf.construction].is_window])
        if a is not None:
            out["gamma_absorp"] = Prior(a, _HANDBOOK["gamma_absorp"][1],
                                        "area-weighted outer solar absorptance of the IDF's "
                                        "exterior walls")
        g = _area_mean([(w.shgc, w.area) for w in wins if w.shgc is not None])
        if g is not None:
            out["gamma_winSolAbs"] = Prior(g, max(window_sd * g, 0.05),
                                           "area-weighted window SHGC of the IDF")
    if positive not in POSITIVE_PRIORS:
        raise ValueError(f"positive={positive!r}: use one of {', '.join(POSITIVE_PRIORS)}")
    if positive == "log":
        out.update({n: Prior(p.mean, p.sd, p.source, log=True)
                    for n, p in out.items() if n in POSITIVE})
    for name in params.param_names:
        if name.startswith("c_IG"):
            out[name] = Prior(*_C_IG)
    return {n: out[n] for n in params.param_names}


def _area_mean(pairs: list[tuple[float, float]]) -> float | None:
    """Area-weighted mean of (value, area [m2]) pairs; None when no area."""
    area = sum(a for _, a in pairs if a > 0)
    return sum(v * a for v, a in pairs if a > 0) / area if area > 0 else None


def _arrays(priors: Mapping[str, Prior], names: list[str]) -> tuple[np.ndarray, np.ndarray]:
    missing = [n for n in names if n not in priors]
    if missing:
        raise ValueError(f"no prior for {missing}; give one per parameter "
                         "(building_priors makes them)")
    return (np.array([priors[n].mean for n in names]), np.array([priors[n].sd for n in names]))


def _log_mask(priors: Mapping[str, Prior], names: list[str]) -> np.ndarray:
    return np.array([priors[n].log for n in names], dtype=bool)


def _log_sds(priors: Mapping[str, Prior], names: list[str], mask: np.ndarray) -> np.ndarray:
    return np.array([priors[n].log_sd for n, m in zip(names, mask) if m])


def prior_residuals(theta: np.ndarray, priors: Mapping[str, Prior], names: list[str],
                    sigma_e: float) -> np.ndarray:
    """Prior rows of the MAP least squares: ``sigma_e (theta - mu) / sd`` [K], and
    ``sigma_e ln(theta / mu) / (sd / mu)`` for a log-normal prior (theta floored at 1e-12)."""
    mu, sd = _arrays(priors, names)
    theta = np.asarray(theta, float)
    out = (theta - mu) / sd
    log = _log_mask(priors, names)
    if log.any():
        out[log] = np.log(np.maximum(theta[log], 1e-12) / mu[log]) / _log_sds(priors, names, log)
    return sigma_e * out


def prior_jacobian(priors: Mapping[str, Prior], names: list[str], sigma_e: float,
                   theta: np.ndarray | None = None) -> np.ndarray:
    """Jacobian of :func:`prior_residuals` (diagonal); ``theta`` is needed when a prior is
    log-normal (its row's slope is ``sigma_e mu / (sd theta)``)."""
    _, sd = _arrays(priors, names)
    diag = 1.0 / sd
    log = _log_mask(priors, names)
    if log.any():
        if theta is None:
            raise ValueError("a log-normal prior's Jacobian depends on theta; pass it")
        t = np.maximum(np.asarray(theta, float)[log], 1e-12)
        diag[log] = 1.0 / (_log_sds(priors, names, log) * t)
    return np.diag(sigma_e * diag)
