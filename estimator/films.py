"""Inside films as natural convection alone, by EnergyPlus's inside convection algorithm.

With the star of long-wave exchange between a room's faces (``ModelOptions.interior_radiation
="star"``) a face's film to the room air is convection alone. These are its sizes, the priors'
means of the fitted films (:mod:`~zonecast.estimator.priors`) and the known film of a roof's
inner face (``ModelOptions.roof_inside="known"``). A module of its own because both the
network (:mod:`~zonecast.estimator.rc.network`) and the priors, which import the network,
need them.
"""

from __future__ import annotations

from zonecast.estimator.idf import Building

#: inside films as convection alone, for a structure whose faces exchange long-wave radiation
#: among themselves (``ModelOptions.interior_radiation="star"``): EnergyPlus's "Simple"
#: natural-convection coefficients, vertical 3.08, horizontal 4.04 (heat flowing up) and
#: 0.95 (down); a floor or ceiling sees both directions over a day
_HORIZONTAL = ("natural convection at a horizontal face, 0.95-4.04 by the direction of heat "
               "flow (EnergyPlus Simple)")
CONVECTIVE_FILMS = {
    "gamma_IW": (3.1, 1.5, "natural convection at a vertical face (EnergyPlus Simple 3.08)"),
    "gamma_floor": (2.5, 1.5, _HORIZONTAL),
    "gamma_ceil": (2.5, 1.5, _HORIZONTAL),
}
#: inside films as convection alone for a file whose inside convection is EnergyPlus's TARP
#: (its default) or another natural-convection correlation: Walton's coefficients at a
#: face-to-air difference of 1 K, vertical 1.31 |dT|^1/3, horizontal 1.52 |dT|^1/3 (heat
#: flowing up) and 0.76 |dT|^1/3 (down), the mean of both directions for floors and
#: ceilings; the same relative spread as :data:`CONVECTIVE_FILMS` (EnergyPlus Engineering
#: Reference, "Inside Convection Algorithms"; the family's faces are 0.2-1.9 K from their
#: air, benchmarks/bench_convection_regimes.py)
_TARP_HORIZONTAL = ("natural convection at a horizontal face, 0.76-1.52 W/m2K at 1 K by the "
                    "direction of heat flow (Walton, EnergyPlus TARP)")
TARP_FILMS = {
    "gamma_IW": (1.3, 0.65,
                 "natural convection at a vertical face (Walton, EnergyPlus TARP, 1.31 at 1 K)"),
    "gamma_floor": (1.1, 0.65, _TARP_HORIZONTAL),
    "gamma_ceil": (1.1, 0.65, _TARP_HORIZONTAL),
}
#: EnergyPlus inside algorithms whose natural convection is Walton's (or of its size): the
#: file's films take :data:`TARP_FILMS` with ``films="idf"``; the others (``Simple``,
#: ``CeilingDiffuser``) :data:`CONVECTIVE_FILMS`
NATURAL_ALGORITHMS = ("tarp", "adaptiveconvectionalgorithm", "astmc1340")


def convective_films(building: Building | None) -> dict[str, tuple[float, float, str]]:
    """The convective films' priors (mean, sd, source) for ``building``'s declared inside
    convection algorithm (:attr:`~zonecast.estimator.idf.Building.inside_convection`):
    :data:`TARP_FILMS` for TARP (EnergyPlus's default) and the other natural-convection
    correlations, :data:`CONVECTIVE_FILMS` (EnergyPlus's ``Simple`` constants) otherwise
    or without a building."""
    algo = getattr(building, "inside_convection", None)
    if algo is not None and algo.lower() in NATURAL_ALGORITHMS:
        return {k: (m, sd, f"{src}; the IDF's inside algorithm {algo}")
                for k, (m, sd, src) in TARP_FILMS.items()}
    return dict(CONVECTIVE_FILMS)
