"""Thermal submodel (A_t, B_t) and external heat flux models of paper sec:model.

:func:`build_structure` turns a :class:`~zonecast.estimator.idf.Building` plus the
model zones and VAV boxes into an :class:`RCStructure`: the continuous bilinear
model of paper eq:ct_model with every matrix stored as its parameter-free part
plus one piece per parameter, so that for the seven matrix parameters
theta = [gamma_EW, gamma_IW, gamma_floor, gamma_ceil, gamma_absorp,
gamma_winSolAbs, U_win]::

    A(theta)   = A_0   + sum_p theta_p A_p
    B_v(theta) = B_v,0 + sum_p theta_p B_v,p

B_IG, B_xu_j, B_vu_j and C do not depend on parameters.

External heat flux models, exactly as the paper:

* building hull, eq:q_bh -- exterior-surface convection gamma_EW a_EW (Ta - x)
  and solar absorption gamma_absorp a_EW v_sol on the *outer face node* of each
  exterior opaque element; window transmission U_win a_win (Ta - x) and
  gamma_winSolAbs a_win v_sol on the room air;
* HVAC, eq:q_hvac -- c_p sum_{j in B_i} u_j (v_Ts - x_i) on room air;
* internal gains, eq:q_ig -- a_floor,i (c_IG + f_IG) on room air.

Disturbance order is the paper's, v = [Ta, Ts, solE, solS, solW, solN], with the global
horizontal irradiance solH appended for roofs (``ModelOptions.roof_solar``).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.sparse as sp
from zonecast.estimator import outside_films
from zonecast.estimator.films import convective_films
from zonecast.estimator.idf import DEFAULT_SOLAR_ABSORPTANCE, Building, Construction, Surface
from zonecast.estimator.rc.elements import (
    ADMITTANCE_TOLERANCE,
    FINE_SECTION_TIME,
    NodeLayout,
    admittance_error,
    discretise_layers,
)
from zonecast.estimator.shading import FacadeShading, WindowShading

__all__ = [
    "CP_AIR",
    "DISTURBANCES",
    "RHO_AIR",
    "SOLAR_COLUMNS",
    "ModelDefinitionError",
    "ModelOptions",
    "RCStructure",
    "StateLabel",
    "build_structure",
    "facade_of",
    "sky_share",
]

#: Disturbance vector, paper order (sec:model): ambient, supply air, solar E, S, W, N; then
#: the global irradiance on a horizontal plane (roofs, ``ModelOptions.roof_solar``), which
#: the paper's model does not have.
DISTURBANCES = ("Ta", "Ts", "solE", "solS", "solW", "solN", "solH")
#: The solar columns of v: the four facades, then horizontal.
SOLAR_COLUMNS = DISTURBANCES[2:]
#: conductance between a ground-contact outer face and the ground temperature [W/(m2 K)]:
#: EnergyPlus puts the face at the ground temperature; 100 W/m2K holds it there within a few
#: per cent of the drop across any slab (U <= 5 W/m2K) without stiffening the model beyond
#: its film-coupled massless faces (docs/model.md "Ground contact")
GROUND_CONDUCTANCE = 100.0
#: linearised long-wave coefficient between an opaque exterior face and the sky [W/(m2 K)]:
#: eps sigma (T_s^2 + T_sky^2)(T_s + T_sky) with eps = 0.9 (EnergyPlus's default thermal
#: absorptance) between a face at 12 degC and a sky at -8 degC (docs/model.md "Sky")
SKY_RADIATION = 4.2
#: linearised long-wave coefficient between the inside faces of a room [W/(m2 K)]:
#: 4 eps sigma T^3 with eps = 0.9 (EnergyPlus's default thermal absorptance) at 20 degC, the
#: radiative share of a combined inside film (ISO 6946 h_r0 = 5.7 for eps = 1); with
#: ``interior_radiation="star"`` (docs/model.md "Interior long-wave exchange")
INTERIOR_RADIATION = 5.1
#: heat capacity of a window's glass [J/(m2 K)] (one 6 mm pane: 2500 kg/m3 x 840 J/(kg K));
#: its node with ``interior_radiation="star"``
GLASS_CAPACITY = 12600.0
#: natural convection at the inside faces of a room [W/(m2 K)]: EnergyPlus's "Simple"
#: vertical coefficient (3.08), for the faces that pass on the long-wave heat of
#: ``envelope_radiation="room"`` (docs/model.md "Envelope faces' long-wave exchange")
ROOM_FACE_CONVECTION = 3.08
#: time constant [s] with which the outer face of an ``Adiabatic`` surface follows its inner
#: face (``adiabatic="mirror"``): its node gets C_face / MIRROR_TIME [W/K] from the inner
#: face's temperature, a quarter of the 15-min step (EnergyPlus puts the outer face at the
#: inner face's temperature of its previous time step; docs/model.md "Adiabatic surfaces")
MIRROR_TIME = 225.0
#: U-factor [W/(m2 K)] of windows whose IDF gives none (layered glazing) when no window of
#: the building has one: double glazing in an aluminium frame (the U_win prior's mean)
WINDOW_U_DEFAULT = 2.8
#: [W/(m2 K)] a rated window U-factor at or above this is single glazing (clear single
#: panes rate 5-6, double 1.5-3.3), for the panes of ``ModelOptions.window_angle``
SINGLE_PANE_U = 4.0
#: ``ModelOptions.layers``: how constructions become nodes
LAYERS = ("lumped", "fine", "fine_roofs", "roofs_admittance", "admittance_but_facades")
#: Specific heat capacity of air c_p [J/(kg K)].
CP_AIR = 1005.0
#: Air density for room air capacity [kg/m3].
RHO_AIR = 1.2

# parameter indices of the seven matrix parameters (same order as rc.parameters.PHYSICAL)
EW, IW, FLOOR, CEIL, ABSORP, WINSOL, UWIN = range(7)
#: index of the roofs' own outside film (``ModelOptions.roof_exterior="own"``), the first
#: extra matrix parameter (rc.parameters.EXTRA["gamma_roof"])
ROOF = 7
#: inside convection of horizontal faces when a room's air is warmer than them (its boxes
#: reheat), relative to the fitted films (``ModelOptions.inside_convection="regime"``): the
#: fitted γ_floor and γ_ceil are those of the usual regime, faces warmer than the air (the
#: floor's heat rises, unstable; the ceiling's is trapped, stable); reheated air above them
#: swaps the regimes. Walton's natural-convection correlations for horizontal faces (TARP,
#: EnergyPlus's default inside algorithm) give stable / unstable = (1.810 / 2.382) /
#: (9.482 / 6.238) = 0.50 at the same |ΔT| (docs/model.md "Inside convection regimes")
REGIME_FLOOR = 0.5
REGIME_CEILING = 2.0
#: a box's discharge air this far above the supply air [K] marks its room's air warmer
#: than its faces (``ModelOptions.inside_convection="regime"``)
REGIME_RISE = 1.0
#: ways to model a roof's outer face (``ModelOptions.roof_exterior``)
ROOF_EXTERIORS = ("fitted", "idf", "absorptance", "climate", "own", "balance", "auto")
#: ways to model a roof's inner face (``ModelOptions.roof_inside``)
ROOF_INSIDES = ("fitted", "known")
#: the sky model of roofs with ``roof_exterior="balance"`` when ``ModelOptions.sky`` is
#: "none": the cloud cover's sky, clear where the site has no cover reading
BALANCE_SKY = "cloud"
#: outside film of a roof with ``ModelOptions.roof_exterior == "idf"`` [W/(m2 K)]: the
#: handbook's combined film, γ_EW's start and prior mean (parameters.PHYSICAL)
ROOF_FILM = 25.0


def outer_absorptance(construction) -> float:
    """Solar absorptance [-] of a construction's outer face: its outside layer's (0.7,
    EnergyPlus's default, for a construction without layers)."""
    layers = getattr(construction, "layers", ())
    return float(layers[0].solar_absorptance) if layers else DEFAULT_SOLAR_ABSORPTANCE


_INSIDE_GAMMA = {"Wall": IW, "Floor": FLOOR, "Ceiling": CEIL, "Roof": CEIL}
# the other side of an interzone surface faces the mirrored type
_MIRROR = {"Wall": "Wall", "Floor": "Ceiling", "Ceiling": "Floor", "Roof": "Floor"}
_FACADES = {90.0: "solE", 180.0: "solS", 270.0: "solW", 0.0: "solN"}


class ModelDefinitionError(ValueError):
    """The zones/boxes given for the model do not fit the building."""


@dataclass(frozen=True)
class StateLabel:
    """What a state is.

    Attributes
    ----------
    kind : str
        ``"room_air"`` (a room in a model zone), ``"unmeasured_air"`` (a room in
        no model zone, e.g. a plenum), or the element kind ``"wall"``,
        ``"floor"``, ``"ceiling"``, ``"roof"``, ``"floor_ceiling"``,
        ``"internal_mass"``, or ``"window"`` (a window's glass, with
        ``interior_radiation="star"``).
    room : str
        Room (EnergyPlus zone) the state belongs to; for elements the room on the
        element's inside face.
    element : str or None
        Surface (or surface pair ``A|B``, internal mass) name.
    layer : int or None
        Node index from the outside face (0) to the inside face.
    """

    kind: str
    room: str
    element: str | None = None
    layer: int | None = None

    def __str__(self) -> str:
        if self.element is None:
            return f"{self.kind}:{self.room}"
        return f"{self.kind}:{self.element}:{self.layer}"


@dataclass(frozen=True)
class ModelOptions:
    """Modelling choices that are not parameters.

    Attributes
    ----------
    window_angle : {"none", "glass"}
        How the facade columns of v weigh the sun's angle of incidence: "none" (the
        paper's, the default) takes the global irradiance on the facade; "glass" weighs
        each part by what a window's panes let through at its angle relative to normal
        incidence (beam and circumsolar by the incidence angle, sky, horizon and ground by
        their hemispherical averages;
        :func:`~zonecast.estimator.solar.window_transmission`). The columns follow the
        windows, whose solar gain is an order of magnitude larger than the opaque walls'
        (as with the windows' shading). Panes from the windows' rated U-factor
        (:attr:`RCStructure.window_panes`).
    roof_solar : {"horizontal", "mean", "none"}
        Solar input on roofs and other surfaces tilted less than 60 deg from
        horizontal (their opaque outer faces and skylights): the global horizontal
        irradiance (v's ``solH`` column; the default since 2026-11-25, chosen on the
        family's training members with roofs, docs/benchmarks.md), the mean of the four
        facade irradiances (the paper's v has no horizontal column; the default before, and
        what model files without the option were built with), or none.
    ground : {"idf", "adiabatic"}
        Ground-contact outer faces: held near the IDF's monthly temperature under the
        building (Site:GroundTemperature:BuildingSurface, EnergyPlus's boundary condition)
        through :data:`GROUND_CONDUCTANCE`, a scheduled input per surface
        (:attr:`RCStructure.scheduled`); or no heat flux (the structure before
        2026-11-24; model files written before read as this).
    rho_air : float
        Air density for room capacities [kg/m3].
    cp_air : float
        c_p of air [J/(kg K)] (paper eq:q_hvac).
    window_solar : {"surfaces", "floor", "air"}
        Where the solar heat entering through windows, gamma_winSolAbs a_win v_sol
        (paper eq:q_bh), is put: ``"surfaces"`` (default) shares it between the inside
        faces of the room's floors (``floor_share``, as EnergyPlus puts transmitted beam
        on the floor) and the inside faces of its other elements — walls, ceilings,
        internal mass — by area (diffuse and reflected solar); ``"floor"`` puts it all on
        the floors; ``"air"`` on the room air (the paper). A room without floors or
        elements keeps it on the air. Same parameter in every case (docs/model.md).
    floor_share : float
        Share [-] of the window solar on the floors with ``window_solar="surfaces"``.
    facades : {"building", "cardinal"}
        The four solar columns of v: irradiance on facades facing the building's own
        four directions (:func:`facade_rotation`; a rotated plan's facades get their own
        sun), or facing E/S/W/N whatever the plan (the paper; each facade takes the
        nearest).
    infiltration : {"idf", "none"}
        Outdoor air leaking into the rooms: the IDF's ZoneInfiltration:DesignFlowRate
        objects as a fixed conductance rho c_p q between the outdoor air and the room air
        (:class:`~zonecast.estimator.idf.Infiltration`; no parameter; the default since
        2026-11-24, chosen on the family's training members, docs/identification.md), or
        none (the paper). Model files written before carry their own choice. An
        infiltration that follows a Schedule:Compact is a scheduled input instead: a
        box-like airflow rho q F(t) whose supply air is the outdoor air
        (:attr:`RCStructure.scheduled`).
    shading : {"idf", "none"}
        Exterior shading of windows: the IDF's overhangs, fins and shading surfaces shade
        the window irradiance of the solar columns (:attr:`RCStructure.shading`,
        :mod:`~zonecast.estimator.shading`), or nothing shades them (model files written
        before the option existed read as this).
    return_air : {"idf", "none"}
        Return air through a return plenum (the IDF's ``AirLoopHVAC:ReturnPlenum``): each
        box's airflow carries its room's air into the plenum, c_p u_j (x_room - x_plenum)
        (:attr:`RCStructure.return_of_box`; docs/model.md "Return plenum"), or the plenum
        exchanges heat by conduction only (the paper; model files written before the option
        existed read as this).
    sky : {"none", "clear", "iso", "cloud"}
        Long-wave exchange of opaque exterior faces with the sky, which is colder than the
        air: none (the paper; its exterior film gamma_EW exchanges with the air only), or
        each face's sky share F_sky beta = ((1 + cos tilt) / 2)^1.5 (EnergyPlus's, 1 for a
        roof, 0.35 for a wall) exchanges :data:`SKY_RADIATION` with a sky temperature, a
        scheduled input per surface (:attr:`RCStructure.scheduled`): the clear-sky
        temperature of the outdoor air (``"clear"``,
        :func:`~zonecast.estimator.solar.clear_sky_temperature`), or the air temperature
        less the average sky temperature difference of ISO 52016-1 / ISO 13790,
        :data:`~zonecast.estimator.solar.SKY_DEPRESSION_ISO` (``"iso"``), or the
        temperature of a sky under the site's measured cloud cover (``"cloud"``, which
        needs the site's ``points.cloud_cover``;
        :func:`~zonecast.estimator.solar.cloudy_sky_temperature`; docs/model.md "Sky").
    interior_radiation : {"star", "none"}
        Long-wave exchange between the inside faces of a room (``"star"``, the default since
        2026-12-05 with ``adiabatic="mirror"``, chosen on the family's training members;
        model files without the key read as ``"none"``). ``"none"`` (the paper): each
        face exchanges heat with the room air only, through a film coefficient that must
        carry convection and radiation at once (the handbook's combined 8.3 W/m2K for a
        wall). ``"star"``: the faces of a room also exchange long-wave radiation with each
        other through a massless star node, :data:`INTERIOR_RADIATION` A_i to it from each
        face (eliminated: A_i A_j / sum A between each pair of faces), so gamma_IW,
        gamma_floor and gamma_ceil are convection only and the room air answers its own
        heat (reheat, convective gains) as fast as its own capacity lets it, while the
        surfaces share the sun and radiant heat among themselves (EnergyPlus's inside heat
        balance; the star network of ISO 13790 / ISO 52016-1). Each exterior window's glass
        is a node of the network too (:data:`GLASS_CAPACITY`): convection gamma_IW to the
        air, long-wave with the room's faces, and U_win :func:`glass_factor` to the outdoor
        air (the rated U-factor's inside film is the model's own here); before 2026-11-25
        windows took no part (U_win a conductance to the air).
    envelope_radiation : {"none", "room"}
        The inside faces of the envelope (opaque surfaces open to the outdoors or on the
        ground) are colder than the rest of the room in the heating season and draw
        long-wave heat from its other faces, which the air warms by convection. ``"none"``
        (the paper): each face exchanges with the air through its fitted film alone.
        ``"room"``: each envelope face is also linked to its room's air by the series of the
        long-wave exchange with the room's other faces (:data:`INTERIOR_RADIATION`) and
        their convection with the air (:data:`ROOM_FACE_CONVECTION` over their area),
        1 / (1 / h_r + A_i / (h_c A_others)) A_i: the heat an EnergyPlus envelope face
        receives by radiation, taken from the air through the faces that give it, with
        the room's other faces at the air temperature. No parameter; the fitted films
        stay the faces' convection (docs/model.md "Envelope faces' long-wave exchange").
    adiabatic : {"mirror", "zero_flux"}
        The outer face of a surface whose boundary is ``Adiabatic``: no heat flux
        (``"zero_flux"``, what model files without the option were built with), or, as
        EnergyPlus does, held at the temperature of its own inner face (``"mirror"``, the
        default since 2026-12-05 with ``interior_radiation="star"``: the
        surface is its own other side, ExtBoundCond = the surface). The outer face's node
        then gets C_face / :data:`MIRROR_TIME` (x_inner - x_outer) from outside the room's
        balance, the heat the storey above or below would give it, and the slab behind a
        carpet or a suspended ceiling answers its room through that inner face alone
        (EnergyPlus's outer-face flux on a middle floor's ceiling slab is 10 times its
        inner face's). A is then not the symmetric form diag(1/C) K; the integrators take
        the general path, as with return air (docs/model.md "Adiabatic surfaces").
    layers : {"lumped", "fine", "fine_roofs", "roofs_admittance", "admittance_but_facades"}
        How a construction becomes nodes: 2 or 3 per element, BRCM-like (``"lumped"``, what
        model files without the option were built with), or sections of at most
        :data:`~zonecast.estimator.rc.elements.FINE_SECTION_TIME` of diffusion time each
        (``"fine"``), or so for the roofs open to the outdoors alone and lumped elsewhere
        (``"fine_roofs"``); both measured and not adopted. Or, the default since 2026-12-06
        (chosen on the family's training members), so for the roofs open to the outdoors
        whose lumped layout gets the daily admittance of their inside face wrong by more
        than :data:`~zonecast.estimator.rc.elements.ADMITTANCE_TOLERANCE` (EN ISO 13786;
        :func:`~zonecast.estimator.rc.elements.admittance_error`), e.g. a concrete deck
        behind a suspended ceiling, which the lumped layout puts on the tile's face, and
        lumped elsewhere (``"roofs_admittance"``, the default of 2026-12-06's thirty-seventh
        session). Or, the default since the forty-second, the same test for every construction but
        the walls open to the outdoors, whose fine sections the training members' fits
        were measured to prefer lumped (``"admittance_but_facades"``: roofs, internal mass
        such as thick furniture, floors and ceilings to an attic or another zone, interior
        walls); on the family it builds the same states as ``"roofs_admittance"``
        (docs/model.md "States").
    internal_mass : {"both_faces", "one_face"}
        An InternalMass object: one face of its area meets the zone and the back face is
        held as an ``Adiabatic`` surface's outer face (``"one_face"``: EnergyPlus's form,
        the surface its own other side; the default since 2026-12-06's forty-second
        session, chosen on the family's training members), or both faces do
        (``"both_faces"``, what model files without the option were built with;
        docs/model.md "States").
    solar_enclosure : {"air_boundaries", "room"}
        Where a window's transmitted sun lands: on the faces of its room (``"room"``, what
        model files without the option were built with), or, the default since 2026-12-04,
        on the faces of every room joined to it by air boundaries
        (``Construction:AirBoundary``; :attr:`~zonecast.estimator.idf.Building.air_boundaries`),
        which EnergyPlus makes one solar and radiant enclosure (with
        ``internal_gains="idf"`` the gains' radiant share too); a building without air
        boundaries is unchanged (docs/model.md "Air boundaries").
    roof_exterior : {"auto", "fitted", "idf", "absorptance", "climate", "own", "balance"}
        The outer faces of roofs (surfaces of type Roof open to the outdoors). ``"auto"``
        (the default since 2026-12-07, chosen on the family's training members by the
        standing rule; docs/benchmarks.md "The roofs' exterior balance with the meters"):
        ``"balance"`` where the building has such roofs and their climate films can be
        computed (a weather file is known, :attr:`~zonecast.estimator.idf.Building.weather_file`),
        else ``"absorptance"`` with a note saying why; :func:`build_model` stores the
        resolved value in :attr:`RCStructure.options`, so a model file names it. With
        the IDF's solar absorptance of the roof's outer material (EnergyPlus's 0.7 where
        it gives none) and the fitted γ_EW (``"absorptance"``, the default from 2026-12-04
        to 2026-12-07), with the walls' fitted γ_EW
        and γ_absorp (``"fitted"``: the paper's one exterior balance; what model files
        without the option were built with), or with a known film as well (``"idf"``:
        :data:`ROOF_FILM`, the handbook's combined film and γ_EW's prior), or with the film
        of the site's wind climate (``"climate"``: each roof's mean film over the hours of
        the building's weather file by the input's outside convection correlation,
        :func:`~zonecast.estimator.outside_films.climate_films`; measured, not adopted), or
        with a film of their own, fitted: ``"own"`` adds the matrix parameter ``gamma_roof``
        (:data:`ROOF`; its prior is the roofs' climate film,
        :func:`~zonecast.estimator.priors.building_priors`) when the building has a roof open
        to the outdoors; or as EnergyPlus balances a roof's outer face (``"balance"``:
        known convection to the air and long-wave to the sky for its sky share, the sky of
        ``sky`` or else :data:`BALANCE_SKY`, both with the films that carry the sun's heat,
        :func:`~zonecast.estimator.outside_films.sunlit_film_parts`; measured, not
        adopted). With ``"climate"`` and a ``sky`` model the climate film's long-wave sky
        share goes to the sky. Only ``"own"`` adds a parameter; the walls keep γ_EW and
        γ_absorp (docs/model.md "Roofs' own exterior").
    internal_gains : {"air", "idf"}
        Where a room's internal heat a_floor (c_IG + f_IG) goes (paper eq:q_ig): all on the
        room air (the paper), or split as the IDF's People, Lights and equipment objects
        split theirs (:meth:`~zonecast.estimator.idf.Building.gain_split`, weighted by
        design power): the convective share on the air, the radiant share (long-wave and
        visible) on the room's inside faces by area, the lights' return-air share on the
        air of the room's return plenum. No parameter; the heat put in is the same.
    """

    roof_solar: str = "horizontal"
    ground: str = "idf"
    rho_air: float = RHO_AIR
    cp_air: float = CP_AIR
    window_solar: str = "surfaces"
    floor_share: float = 0.25
    infiltration: str = "idf"
    facades: str = "building"
    shading: str = "idf"
    return_air: str = "idf"
    sky: str = "none"
    interior_radiation: str = "star"
    internal_gains: str = "air"
    window_angle: str = "none"
    roof_exterior: str = "auto"
    envelope_radiation: str = "none"
    solar_enclosure: str = "air_boundaries"
    adiabatic: str = "mirror"
    layers: str = "admittance_but_facades"
    internal_mass: str = "one_face"
    inside_convection: str = "constant"
    roof_inside: str = "fitted"

    def __post_init__(self):
        if self.roof_inside not in ROOF_INSIDES:
            raise ModelDefinitionError("roof_inside must be one of "
                                       + ", ".join(map(repr, ROOF_INSIDES)))
        if self.roof_inside == "known" and self.interior_radiation != "star":
            raise ModelDefinitionError(
                "roof_inside='known' gives the roofs' inner faces a convective film, which "
                "leaves their long-wave exchange to interior_radiation='star'; use the star "
                "or roof_inside='fitted'")
        if self.inside_convection not in ("constant", "regime"):
            raise ModelDefinitionError("inside_convection must be 'constant' or 'regime'")
        if self.internal_mass not in ("both_faces", "one_face"):
            raise ModelDefinitionError("internal_mass must be 'both_faces' or 'one_face'")
        if self.layers not in LAYERS:
            raise ModelDefinitionError(f"layers must be one of {', '.join(map(repr, LAYERS))}")
        if self.adiabatic not in ("zero_flux", "mirror"):
            raise ModelDefinitionError("adiabatic must be 'zero_flux' or 'mirror'")
        if self.solar_enclosure not in ("room", "air_boundaries"):
            raise ModelDefinitionError("solar_enclosure must be 'room' or 'air_boundaries'")
        if self.envelope_radiation not in ("none", "room"):
            raise ModelDefinitionError("envelope_radiation must be 'none' or 'room'")
        if self.envelope_radiation != "none" and self.interior_radiation == "star":
            raise ModelDefinitionError("envelope_radiation='room' approximates the star of "
                                       "interior_radiation='star'; choose one of them")
        if self.roof_exterior not in ROOF_EXTERIORS:
            raise ModelDefinitionError("roof_exterior must be one of "
                                       + ", ".join(map(repr, ROOF_EXTERIORS)))
        if self.window_angle not in ("none", "glass"):
            raise ModelDefinitionError("window_angle must be 'none' or 'glass'")
        if self.internal_gains not in ("air", "idf"):
            raise ModelDefinitionError("internal_gains must be 'air' or 'idf'")
        if self.interior_radiation not in ("none", "star"):
            raise ModelDefinitionError("interior_radiation must be 'none' or 'star'")
        if self.sky not in ("none", "clear", "iso", "cloud"):
            raise ModelDefinitionError("sky must be 'none', 'clear', 'iso' or 'cloud'")
        if self.return_air not in ("idf", "none"):
            raise ModelDefinitionError("return_air must be 'idf' or 'none'")
        if self.shading not in ("idf", "none"):
            raise ModelDefinitionError("shading must be 'idf' or 'none'")
        if self.facades not in ("building", "cardinal"):
            raise ModelDefinitionError("facades must be 'building' or 'cardinal'")
        if self.infiltration not in ("none", "idf"):
            raise ModelDefinitionError("infiltration must be 'none' or 'idf'")
        if self.window_solar not in ("air", "floor", "surfaces"):
            raise ModelDefinitionError("window_solar must be 'surfaces', 'floor' or 'air'")
        if not 0.0 <= self.floor_share <= 1.0:
            raise ModelDefinitionError("floor_share must be a fraction in [0, 1]")
        if self.roof_solar not in ("horizontal", "mean", "none"):
            raise ModelDefinitionError("roof_solar must be 'horizontal', 'mean' or 'none'")
        if self.ground not in ("idf", "adiabatic"):
            raise ModelDefinitionError("ground must be 'idf' or 'adiabatic'")


def facade_of(tilt: float, azimuth: float, roof_solar: str = "mean",
              rotation: float = 0.0) -> dict[str, float]:
    """Solar columns (with weights) acting on a surface.

    Parameters
    ----------
    tilt : float
        [deg] 0 facing up, 90 vertical.
    azimuth : float
        [deg] clockwise from north.
    roof_solar : {"horizontal", "mean", "none"}
        As :attr:`ModelOptions.roof_solar`.
    rotation : float
        [deg] the building's facade rotation (:func:`facade_rotation`): the solar columns
        are the irradiances on facades facing 90/180/270/0 deg plus it.

    Returns
    -------
    dict
        Disturbance name -> weight; vertical surfaces take the nearest of the four
        facade directions, surfaces facing down none.
    """
    if tilt > 120.0:
        return {}
    if tilt < 60.0:
        if roof_solar == "horizontal":
            return {"solH": 1.0}
        return {f: 0.25 for f in _FACADES.values()} if roof_solar == "mean" else {}
    diffs = {f: abs((azimuth - a - rotation + 180.0) % 360.0 - 180.0) for a, f in _FACADES.items()}
    return {min(diffs, key=diffs.get): 1.0}


def sky_share(tilt: float) -> float:
    """Share [-] of an exterior face's long-wave exchange that goes to the sky,
    F_sky beta with F_sky = (1 + cos tilt) / 2 and beta = sqrt(F_sky) (EnergyPlus
    Engineering Reference, "Exterior Long-Wavelength Radiation"): 1 for a roof, 0.354 for
    a wall, 0 facing down.

    Parameters
    ----------
    tilt : float
        [deg] 0 facing up, 90 vertical.
    """
    f = 0.5 * (1.0 + np.cos(np.radians(tilt)))
    return float(max(f, 0.0) ** 1.5)


def _window_shading(shaded, window_area: Mapping[str, np.ndarray],
                    notes: list[str]) -> list[dict]:
    """The shaded windows as :attr:`RCStructure.shading` entries: each window's share of
    its facade's exterior window area and its diffuse ratios."""
    totals = np.sum(list(window_area.values()), axis=0) if window_area else np.zeros(4)
    out = []
    for name, col, area, verts, shades in shaded:
        ws = WindowShading(name, col, float(area / totals[col]), verts, shades)
        if ws.shades:  # surfaces behind the window cannot shade it
            out.append(ws.to_dict())
    if out:
        notes.append(f"{len(out)} shaded windows: overhangs, fins and shading surfaces shade "
                     "their facade's solar column (window-area weighted)")
    return out


def facade_rotation(building: Building) -> float:
    """The building's facade rotation [deg] in [-45, 45): the four-fold circular mean of
    the azimuths of its vertical exterior surfaces, weighted by gross area (0 for a plan
    whose facades face E/S/W/N; the building's own rotation for a rectangular plan turned
    by its north axis). Rounded to 0.1 deg; 0 when there are no exterior walls."""
    s = c = 0.0
    for surf in building.surfaces.values():
        if surf.boundary == "Outdoors" and 60.0 <= surf.tilt <= 120.0:
            a = np.radians(4.0 * surf.azimuth)
            s += surf.gross_area * np.sin(a)
            c += surf.gross_area * np.cos(a)
    if s == 0.0 and c == 0.0:
        return 0.0
    rot = round(float(np.degrees(np.arctan2(s, c)) / 4.0), 1)
    return 0.0 if rot == 0.0 else rot  # no negative zero


@dataclass
class RCStructure:
    """Continuous bilinear model, affine in the seven matrix parameters (paper eq:ct_model).

    Attributes
    ----------
    labels : list of StateLabel
    rooms : list of str
        Rooms (EnergyPlus zones) with an air state, in state order (first states).
    zones : dict
        Model zone -> its rooms.
    boxes : dict
        Box id -> room.
    capacity : ndarray
        Heat capacity per state [J/K].
    A0, A_p : sparse matrices
        A = A0 + sum_p theta_p A_p[p] [1/s].
    Bv0, Bv_p : sparse matrices
        B_v = Bv0 + sum_p theta_p Bv_p[p], columns :data:`DISTURBANCES`.
    B_ig : ndarray, shape (n, n_zones)
        [K/s per W/m2], paper eq:q_ig.
    room_of_box : ndarray of int
        State index of each box's room; B_xu_j = -c_p/C e_r e_r^T and
        B_vu_j = c_p/C e_r e_Ts^T for r = room_of_box[j] (paper eq:q_hvac).
    C : ndarray, shape (n_zones, n)
        Air-volume-weighted mean of each zone's rooms.
    notes : list of str
    options : ModelOptions
        The modelling choices the structure was built with.
    window_area : dict
        Room -> exterior window area seen by each solar column E, S, W, N [m2] (the
        weights of gamma_winSolAbs a_win v_sol, wherever :class:`ModelOptions` puts it).
    scheduled : dict
        Scheduled inputs: box id (after the site's boxes in :attr:`boxes`) -> its spec.
        Such an input is a box-like term c_p u (T_supply - x) at one state whose u and
        T_supply are known ahead (:func:`~zonecast.estimator.dataset.with_scheduled` gives
        its columns of u and of the discharge-air rise T_supply - T_s):
        an infiltration that follows a schedule, ``{"flow": [kg/s], "schedule":
        CompactSchedule.to_dict(), "supply": "Ta"}`` at its room's air; a ground contact,
        ``{"flow": G A / c_p, "supply": "ground", "monthly": [12 x degC]}`` at the outer
        face of the surface (:data:`GROUND_CONDUCTANCE`).
    shading : list of dict
        Shaded exterior windows (:meth:`~zonecast.estimator.shading.WindowShading.to_dict`):
        their facade column, share of the facade's window area, polygons and diffuse
        ratios; empty when nothing shades a window. :attr:`facade_shading` applies them.
    return_of_box : ndarray of int or None
        Air state of the return plenum each box's return air flows into, -1 for none (a
        room without a plenum, a scheduled input); None: no return paths. The plenum gains
        c_p u_j (x_room - x_plenum) (:attr:`returns`).
    window_panes : int
        With ``options.window_angle == "glass"``: the glass panes whose angular
        transmission weighs the facade columns (1 when the windows' area-weighted rated
        U-factor is at least :data:`SINGLE_PANE_U`, else 2); 0: no weighting.
    switched : dict
        Links whose conductance follows a room's mode (``options.inside_convection ==
        "regime"``), empty otherwise: ``links`` (k, 3) int, the face's state, the room's
        air state and the mode column; ``area`` (k,) [m2] and ``param`` (k,) the film's
        parameter index (its conductance is area theta_p); ``factor`` (k,) the
        conductance's multiplier at mode 1; ``rooms`` the mode columns' rooms (those with
        VAV boxes). A box's mode column is its room's (:meth:`mode_of_box`).
    """

    labels: list[StateLabel]
    rooms: list[str]
    zones: dict[str, list[str]]
    boxes: dict[str, str]
    capacity: np.ndarray
    A0: sp.csr_matrix
    A_p: list[sp.csr_matrix]
    Bv0: sp.csr_matrix
    Bv_p: list[sp.csr_matrix]
    B_ig: np.ndarray
    room_of_box: np.ndarray
    C: np.ndarray
    cp_air: float
    notes: list[str] = field(default_factory=list)
    areas: dict[str, float] = field(default_factory=dict)
    window_area: dict[str, np.ndarray] = field(default_factory=dict)
    options: ModelOptions = field(default_factory=ModelOptions)
    facade_rotation: float = 0.0
    scheduled: dict[str, dict] = field(default_factory=dict)
    shading: list[dict] = field(default_factory=list)
    return_of_box: np.ndarray | None = None
    window_panes: int = 0
    switched: dict = field(default_factory=dict)
    extra_params: tuple[str, ...] = ()

    @property
    def returns(self) -> tuple[np.ndarray, np.ndarray]:
        """Return air path of each box: (state index of its return plenum's air or -1,
        c_p / C_plenum [1/(s kg/s)] or 0)."""
        nb = len(self.room_of_box)
        ret = (np.full(nb, -1, dtype=np.int64) if self.return_of_box is None
               else np.asarray(self.return_of_box, dtype=np.int64))
        coef = np.where(ret >= 0, self.cp_air / self.capacity[np.maximum(ret, 0)], 0.0)
        return ret, coef

    def switched_conductance(self, theta: np.ndarray) -> np.ndarray:
        """(k,) extra conductance [W/K] of each switched link at mode 1 with the physical
        parameters ``theta``: (factor - 1) area theta_param (empty without links)."""
        sw = self.switched
        if not sw:
            return np.zeros(0)
        return ((np.asarray(sw["factor"]) - 1.0) * np.asarray(sw["area"])
                * np.asarray(theta, dtype=float)[np.asarray(sw["param"])])

    def mode_of_box(self) -> np.ndarray:
        """(n_boxes,) mode column of each box's room, -1 for none (no switched links, a
        scheduled input)."""
        rooms = list(self.switched.get("rooms", ()))
        col = {r: i for i, r in enumerate(rooms)}
        return np.array([col.get(self.boxes[b], -1) if b not in self.scheduled else -1
                         for b in self.boxes], dtype=np.int64)

    @property
    def facade_shading(self):
        """:class:`~zonecast.estimator.shading.FacadeShading` of :attr:`shading` (built
        once), or None when nothing shades a window."""
        if not self.shading:
            return None
        cached = getattr(self, "_facade_shading", None)
        if cached is None:
            cached = FacadeShading.from_list(self.shading)
            object.__setattr__(self, "_facade_shading", cached)
        return cached

    @property
    def hvac_boxes(self) -> list[str]:
        """The site's VAV boxes (every box that is not a scheduled input)."""
        return [b for b in self.boxes if b not in self.scheduled]

    @property
    def facade_azimuths(self) -> tuple[float, float, float, float]:
        """Azimuths [deg] of the facades whose irradiance are v's solar columns (E, S, W,
        N of the building)."""
        return tuple((a + self.facade_rotation) % 360.0 for a in (90.0, 180.0, 270.0, 0.0))

    @property
    def n(self) -> int:
        return len(self.labels)

    def state_counts(self) -> dict[str, int]:
        """Number of states by kind."""
        return dict(Counter(label.kind for label in self.labels))

    def air_states(self, *, measured_only: bool = False) -> np.ndarray:
        """Indices of the air states.

        Parameters
        ----------
        measured_only : bool
            Only rooms in a model zone (``"room_air"``); default also rooms in none
            (``"unmeasured_air"``, e.g. a plenum).
        """
        kinds = ("room_air",) if measured_only else ("room_air", "unmeasured_air")
        return np.flatnonzero([lab.kind in kinds for lab in self.labels])

    def state_zones(self) -> np.ndarray:
        """Model-zone index of every state: the zone of the room the state belongs to (an
        element's inside room), -1 for states of rooms in no model zone."""
        zone_of_room = {r.upper(): i for i, rooms in enumerate(self.zones.values())
                        for r in rooms}
        return np.array([zone_of_room.get(lab.room.upper(), -1) for lab in self.labels],
                        dtype=int)

    def A(self, theta: np.ndarray) -> sp.csr_matrix:
        """Continuous A(theta) [1/s]."""
        self._check_theta(theta)
        out = self.A0.copy()
        for t, piece in zip(theta, self.A_p):
            out = out + t * piece
        return out.tocsr()

    def Bv(self, theta: np.ndarray) -> sp.csr_matrix:
        """Continuous B_v(theta) [K/s per unit of v]."""
        self._check_theta(theta)
        out = self.Bv0.copy()
        for t, piece in zip(theta, self.Bv_p):
            out = out + t * piece
        return out.tocsr()

    def _check_theta(self, theta) -> None:
        if len(theta) != len(self.A_p):
            names = ["the seven", *self.extra_params]
            raise ValueError(f"the structure has {len(self.A_p)} matrix parameters "
                             f"({', '.join(names)}), got {len(theta)}: build the parameters "
                             "with ParameterSet(zones, extra=structure.extra_params)")

    def Bxu_diag(self) -> np.ndarray:
        """-c_p / C_room for each box [1/(s kg/s)] (the one nonzero of B_xu_j)."""
        return -self.cp_air / self.capacity[self.room_of_box]


class _Assembler:
    """Collects conductances (per parameter) and capacities."""

    def __init__(self, n_par: int = 7):
        self.cap: list[float] = []
        self.labels: list[StateLabel] = []
        self.n_par = n_par
        # (i, j, g, p): conductance g * theta_p (p = -1: parameter free) between states
        self.links: list[tuple[int, int, float, int]] = []
        # (i, col, g, p): input coupling to disturbance column col, g * theta_p
        self.inputs: list[tuple[int, int, float, int]] = []
        # (i, g, p): conductance to an input temperature (adds -g to the diagonal)
        self.to_input_temp: list[tuple[int, int, float, int]] = []
        # (i, j, g): heat g (x_j - x_i) into i only, from outside the network (a face held
        # at another state's temperature); parameter free
        self.follows: list[tuple[int, int, float]] = []

    def add_state(self, label: StateLabel, capacity: float) -> int:
        self.labels.append(label)
        self.cap.append(float(capacity))
        return len(self.cap) - 1

    def link(self, i: int, j: int, g: float, p: int = -1) -> None:
        if i != j and g != 0:
            self.links.append((i, j, float(g), p))

    def follow(self, i: int, j: int, g: float) -> None:
        """Heat flow g (x_j - x_i) into state i, not taken from j (one way)."""
        if i != j and g > 0:
            self.follows.append((i, j, float(g)))

    def to_temperature(self, i: int, col: int, g: float, p: int) -> None:
        """Heat flow g theta_p (v_col - x_i)."""
        self.to_input_temp.append((i, col, float(g), p))

    def source(self, i: int, col: int, g: float, p: int) -> None:
        """Heat flow g theta_p v_col."""
        self.inputs.append((i, col, float(g), p))

    def matrices(self) -> tuple[np.ndarray, list, list]:
        n = len(self.cap)
        cap = np.array(self.cap)
        inv = 1.0 / cap
        a_rows: dict[int, tuple[list, list, list]] = {p: ([], [], []) for p in range(-1, self.n_par)}
        b_rows: dict[int, tuple[list, list, list]] = {p: ([], [], []) for p in range(-1, self.n_par)}

        def put(store, p, r, c, val):
            store[p][0].append(r)
            store[p][1].append(c)
            store[p][2].append(val)

        for i, j, g, p in self.links:
            for a, b in ((i, j), (j, i)):
                put(a_rows, p, a, a, -g * inv[a])
                put(a_rows, p, a, b, g * inv[a])
        for i, j, g in self.follows:
            put(a_rows, -1, i, i, -g * inv[i])
            put(a_rows, -1, i, j, g * inv[i])
        for i, col, g, p in self.to_input_temp:
            put(a_rows, p, i, i, -g * inv[i])
            put(b_rows, p, i, col, g * inv[i])
        for i, col, g, p in self.inputs:
            put(b_rows, p, i, col, g * inv[i])

        def build(store, ncol):
            return [
                sp.csr_matrix((store[p][2], (store[p][0], store[p][1])), shape=(n, ncol))
                for p in range(-1, self.n_par)
            ]

        return cap, build(a_rows, n), build(b_rows, len(DISTURBANCES))


def _resolve(names: Sequence[str], table: Mapping[str, object], what: str) -> list[str]:
    out = []
    for name in names:
        try:
            out.append(Building.find(table, str(name), what))
        except KeyError as exc:
            raise ModelDefinitionError(str(exc.args[0])) from None
    return out


def _add_element(
    asm: _Assembler,
    kind: str,
    name: str,
    room_state: Mapping[str, int],
    layout: NodeLayout,
    area: float,
    inside_room: str,
    inside_gamma: int,
    inside_film: float | None = None,
) -> list[int]:
    """Element nodes with conduction links; the inside face convects to its room with the
    fitted film ``inside_gamma`` (a parameter index) or, given, the known ``inside_film``
    [W/(m2 K)]."""
    nodes = [
        asm.add_state(StateLabel(kind, inside_room, name, k), layout.capacities[k] * area)
        for k in range(layout.n)
    ]
    for k, r in enumerate(layout.resistances):
        asm.link(nodes[k], nodes[k + 1], area / r)
    if inside_film is None:
        asm.link(nodes[-1], room_state[inside_room], area, inside_gamma)
    else:
        asm.link(nodes[-1], room_state[inside_room], inside_film * area, -1)
    return nodes


def _mirror(asm: _Assembler, nodes: Sequence[int]) -> None:
    """An element that is its own other side (an ``Adiabatic`` surface, EnergyPlus's internal
    mass): its outer face follows its inner face's temperature (docs/model.md "Adiabatic
    surfaces")."""
    asm.follow(nodes[0], nodes[-1], asm.cap[nodes[0]] / MIRROR_TIME)


def glass_factor(u_value: float) -> float:
    """Ratio [-] of a window's glass-to-outdoor conductance to its U-factor.

    A window's U-factor (rated, with standard films) is air to air; with its glass as a
    node (``interior_radiation="star"``) the inside film is the model's own (convection to
    the air, long-wave to the other faces), so the node's conductance to the outdoor air is
    1 / (1/U - 1/h_i) with EnergyPlus's inside film of the simple glazing model,
    h_i = 0.359073 ln U + 6.949915 for U < 5.85 W/(m2 K), else 1.788041 U - 2.209041
    (EnergyPlus Engineering Reference, "Simple Window Model"); U_win scales it.
    """
    u = float(min(max(u_value, 0.1), 7.0))
    h_i = 0.359073 * np.log(u) + 6.949915 if u < 5.85 else 1.788041 * u - 2.209041
    return 1.0 / (1.0 - u / h_i)


def interior_radiation_links(faces: Sequence[tuple[int, float]],
                             h_r: float = INTERIOR_RADIATION) -> list[tuple[int, int, float]]:
    """Face-to-face conductances [W/K] of a room's star network with its node eliminated.

    Each face i (state, area A_i [m2]) is linked to a massless star node by h_r A_i; the
    node's elimination (a star-mesh transform) leaves g_ij = h_r A_i A_j / sum_k A_k between
    every pair, which passes the same heat for any face temperatures. A state listed twice
    (both faces of one node) counts once with the summed area.
    """
    area: dict[int, float] = {}
    for node, a in faces:
        area[node] = area.get(node, 0.0) + float(a)
    total = sum(area.values())
    nodes = sorted(area)
    if total <= 0:
        return []
    return [(i, j, h_r * area[i] * area[j] / total)
            for k, i in enumerate(nodes) for j in nodes[k + 1:]]


def _interior_radiation(asm: _Assembler, floor_faces: Mapping[str, list],
                        other_faces: Mapping[str, list]) -> int:
    """Add every room's long-wave star network (parameter-free links); returns the count."""
    count = 0
    for room in sorted(set(floor_faces) | set(other_faces)):
        for i, j, g in interior_radiation_links(floor_faces.get(room, [])
                                                + other_faces.get(room, [])):
            asm.link(i, j, g)
            count += 1
    return count


def envelope_radiation_conductance(area: float, others: float,
                                   h_r: float = INTERIOR_RADIATION,
                                   h_c: float = ROOM_FACE_CONVECTION) -> float:
    """Conductance [W/K] between an envelope face of ``area`` [m2] and its room's air
    through the room's other faces (``others`` [m2]): long-wave exchange h_r A in series with
    their convection h_c A_others (``ModelOptions.envelope_radiation="room"``)."""
    if area <= 0 or others <= 0:
        return 0.0
    return area / (1.0 / h_r + area / (h_c * others))


def _envelope_radiation(asm: _Assembler, envelope: Sequence[tuple[str, int, float]],
                        room_state: Mapping[str, int], floor_faces: Mapping[str, list],
                        other_faces: Mapping[str, list]) -> int:
    """Link each envelope face to its room's air (:func:`envelope_radiation_conductance`,
    parameter-free); returns the number of faces linked."""
    env_area: dict[str, float] = {}
    for room, _, a in envelope:
        env_area[room] = env_area.get(room, 0.0) + a
    others = {room: sum(x for _, x in floor_faces.get(room, []) + other_faces.get(room, []))
              - env for room, env in env_area.items()}
    count = 0
    for room, node, a in envelope:
        g = envelope_radiation_conductance(a, others[room])
        if g > 0:
            asm.link(node, room_state[room], g)
            count += 1
    return count


def solar_enclosures(air_boundaries: Sequence[tuple[str, str, float]]) -> dict[str, list[str]]:
    """Room -> the sorted rooms of its enclosure (itself included): the connected groups of
    rooms joined by air boundaries, which EnergyPlus treats as one solar and radiant
    enclosure; rooms without an air boundary are not listed."""
    parent: dict[str, str] = {}

    def find(x: str) -> str:
        while parent.setdefault(x, x) != x:
            x = parent[x]
        return x

    for a, b, _ in air_boundaries:
        parent[find(a)] = find(b)
    groups: dict[str, list[str]] = {}
    for room in parent:
        groups.setdefault(find(room), []).append(room)
    return {room: sorted(members) for members in groups.values() for room in members}


def _solar_targets(opts: ModelOptions, floors: list, others: list,
                   air: int) -> list[tuple[int, float]]:
    """(state, share) pairs that receive a window's solar heat (shares sum to 1)."""
    def spread(faces, weight):
        total = sum(a for _, a in faces)
        return [(node, weight * a / total) for node, a in faces] if total > 0 else []

    if opts.window_solar == "floor":
        targets = spread(floors, 1.0)
    elif opts.window_solar == "surfaces":
        share = opts.floor_share if floors and others else (1.0 if floors else 0.0)
        targets = spread(floors, share) + spread(others, 1.0 - share)
    else:
        targets = []
    return targets or [(air, 1.0)]


def _gain_targets(building: Building, room: str, room_state: Mapping[str, int],
                  floors: list, others: list, glass: float) -> list[tuple[int, float]]:
    """(state, share) pairs of a room's internal heat (shares sum to 1): the IDF's
    convective share on the room air, its radiant share on the room's inside faces by area
    (the windows' share, which has no node, on the air), its return-air share on the air
    of the room's return plenum (the room air without one); :meth:`Building.gain_split`."""
    conv, rad, ret = building.gain_split(room)
    air = room_state[room]
    plenum = room_state.get(building.return_plenum.get(room, ""), air)
    faces = list(floors) + list(others)
    total = sum(a for _, a in faces) + glass
    out = [(air, conv + (rad * glass / total if total > 0 else rad)), (plenum, ret)]
    if total > 0:
        out += [(node, rad * a / total) for node, a in faces]
    merged: dict[int, float] = {}
    for node, share in out:
        if share > 0:
            merged[node] = merged.get(node, 0.0) + share
    return list(merged.items())


def _auto_roof_exterior(building: Building, roofs: Sequence[str], notes: list[str]
                        ) -> tuple[str, dict[str, tuple[float, float]] | None]:
    """``ModelOptions(roof_exterior="auto")`` resolved for ``building`` and its ``roofs``
    (surfaces of type Roof open to the outdoors): ``"balance"`` with the roofs' film parts
    (:func:`~zonecast.estimator.outside_films.climate_film_parts`, weighted by the sun) where
    there are roofs and those can be computed, else ``"absorptance"`` and None (a note says
    why when there are roofs)."""
    if not roofs:
        return "absorptance", None
    try:
        parts = outside_films.climate_film_parts(building, roofs, weight="sun")
    except ValueError as err:
        notes.append("roofs' outer faces with the fitted film (roof_exterior 'absorptance'), "
                     f"not the exterior balance: {err}")
        return "absorptance", None
    return "balance", parts


def build_structure(
    building: Building,
    zones: Mapping[str, Sequence[str]],
    boxes: Mapping[str, str],
    options: ModelOptions | None = None,
) -> RCStructure:
    """Build the continuous bilinear RC model of paper eq:ct_model, affine in the parameters.

    Parameters
    ----------
    building : Building
        From :func:`zonecast.estimator.idf.read_building`.
    zones : mapping
        Model zone -> EnergyPlus zone names (rooms); names are case-insensitive.
        Rooms in no model zone (plenums, attics) become ``unmeasured_air`` states.
    boxes : mapping
        VAV box id -> the room it serves.
    options : ModelOptions, optional

    Returns
    -------
    RCStructure
    """
    opts = options or ModelOptions()
    if not zones:
        raise ModelDefinitionError("give at least one model zone (zone name -> EnergyPlus zones)")
    zone_rooms = {str(z): _resolve(list(rooms), building.zones, "EnergyPlus zone")
                  for z, rooms in zones.items()}
    for z, rooms in zone_rooms.items():
        if not rooms:
            raise ModelDefinitionError(f"model zone {z!r} has no rooms")
    seen: dict[str, str] = {}
    for z, rooms in zone_rooms.items():
        for r in rooms:
            if r in seen:
                raise ModelDefinitionError(
                    f"room {r!r} is in model zones {seen[r]!r} and {z!r}; a room belongs to one zone"
                )
            seen[r] = z
    box_rooms = {str(b): _resolve([room], building.zones, f"room of box {b!r}")[0]
                 for b, room in boxes.items()}
    for b, room in box_rooms.items():
        if room not in seen:
            raise ModelDefinitionError(
                f"box {b!r} serves {room!r}, which is in no model zone; add the room to a zone"
            )

    notes: list[str] = []
    roofs = [n for n, f in building.surfaces.items()
             if f.boundary == "Outdoors" and f.surface_type == "Roof"]
    climate: dict[str, tuple[float, float]] | None = None
    if opts.roof_exterior == "auto":
        resolved, climate = _auto_roof_exterior(building, roofs, notes)
        opts = replace(opts, roof_exterior=resolved)
    own_roof = opts.roof_exterior == "own" and bool(roofs)
    asm = _Assembler(8 if own_roof else 7)
    rotation = facade_rotation(building) if opts.facades == "building" else 0.0
    # the roofs' sky model: the walls' (opts.sky), or with "balance" at least the cloud's
    roof_sky = (BALANCE_SKY if opts.roof_exterior == "balance" and opts.sky == "none"
                else opts.sky)
    if opts.roof_exterior in ("climate", "balance") and climate is None:
        try:
            climate = outside_films.climate_film_parts(
                building, roofs,
                weight="sun" if opts.roof_exterior == "balance" else "hours")
        except ValueError as err:
            raise ModelDefinitionError(f"roof_exterior={opts.roof_exterior!r}: {err}") from None
    climate = climate or {}
    if climate:
        notes.append("roofs' outside films of the site's wind climate (convection + "
                     "long-wave): " + ", ".join(f"{n} {c:.1f} + {r:.1f}"
                                                for n, (c, r) in climate.items())
                     + " W/(m2 K)" + ("; the long-wave's sky share to the sky"
                                      if roof_sky != "none" else ""))
    roof_film = None  # the roofs' known inside film (roof_inside="known")
    if opts.roof_inside == "known":
        roof_film, _, source = convective_films(building)["gamma_ceil"]
        notes.append(f"roofs' inside film known, {roof_film:.2f} W/(m2 K): {source}")
    if rotation:
        notes.append(f"facades rotated {rotation:+.1f} deg from E/S/W/N: the solar columns are "
                     "the irradiances on the building's own facades")
    # room air states first: rooms of model zones in zone order, then unmeasured rooms
    rooms = [r for rs in zone_rooms.values() for r in rs]
    rooms += [r for r in building.zones if r not in seen]
    room_state: dict[str, int] = {}
    for r in rooms:
        kind = "room_air" if r in seen else "unmeasured_air"
        room_state[r] = asm.add_state(
            StateLabel(kind, r), opts.rho_air * opts.cp_air * building.zones[r].volume
        )

    layouts: dict[str, NodeLayout] = {}

    def layout_of(cons: Construction, roof: bool = False, facade: bool = False,
                  tested: bool = True) -> NodeLayout:
        fine = opts.layers == "fine" or (opts.layers == "fine_roofs" and roof)
        error = None
        if tested and ((opts.layers == "roofs_admittance" and roof)
                       or (opts.layers == "admittance_but_facades" and not facade)):
            error = admittance_error(cons.layers, layout_of(cons, tested=False))
            fine = abs(error) > ADMITTANCE_TOLERANCE
        key = f"{cons.name}|fine" if fine else cons.name
        if key not in layouts:
            layouts[key] = discretise_layers(cons.layers, FINE_SECTION_TIME if fine else None)
            if error is not None and fine:
                notes.append(f"construction {cons.name}: its 2- or 3-node layout is "
                             f"{error:+.0%} off the daily inside admittance, so it is resolved "
                             f"into {layouts[key].n} nodes (ModelOptions.layers)")
        return layouts[key]

    surfaces = building.surfaces
    skey = {k.lower(): k for k in surfaces}
    done: set[str] = set()
    area_ext = area_win = 0.0
    scheduled: dict[str, dict] = {}
    # scheduled inputs at a face (ground, sky): box -> (room, state of its face)
    ground_boxes: dict[str, tuple[str, int]] = {}
    # room -> (face node, area) of the element faces exposed to the room's air: floors, and
    # every other element (walls, ceilings, roofs, doors, internal mass)
    floor_faces: dict[str, list[tuple[int, float]]] = {}
    other_faces: dict[str, list[tuple[int, float]]] = {}

    # (room, inside face node, area) of the envelope's opaque faces (envelope_radiation)
    envelope: list[tuple[str, int, float]] = []

    def face(surface: Surface, room: str, node: int) -> None:
        """Record an element face of ``surface`` exposed to ``room``'s air."""
        kind = floor_faces if surface.surface_type == "Floor" else other_faces
        kind.setdefault(room, []).append((node, surface.area))

    n_mirror = 0
    for name in sorted(surfaces):
        if name in done:
            continue
        s: Surface = surfaces[name]
        done.add(name)
        if s.area <= 0:
            continue
        cons = building.constructions[s.construction]
        layout = layout_of(cons, roof=s.surface_type == "Roof" and s.boundary == "Outdoors",
                           facade=s.surface_type == "Wall" and s.boundary == "Outdoors")
        inside_g = _INSIDE_GAMMA.get(s.surface_type, IW)
        kind = s.surface_type.lower()
        if s.parent is not None:  # doors
            kind = "wall"
        if s.boundary == "Surface" and s.boundary_object:
            other_name = skey.get(s.boundary_object.lower())
            if other_name is None:
                raise ModelDefinitionError(
                    f"surface {name!r} faces {s.boundary_object!r}, which is not a surface"
                )
            other = surfaces[other_name]
            done.add(other_name)
            if {s.surface_type, other.surface_type} & {"Floor", "Ceiling", "Roof"}:
                kind = "floor_ceiling"
            label = name if other_name == name else f"{name}|{other_name}"
            nodes = _add_element(asm, kind, label, room_state, layout, s.area, s.zone, inside_g)
            outer_g = _INSIDE_GAMMA.get(other.surface_type, IW)
            asm.link(nodes[0], room_state[other.zone], s.area, outer_g)
            face(s, s.zone, nodes[-1])
            face(other, other.zone, nodes[0])
        elif s.boundary == "Zone" and s.boundary_object:
            other_zone = _resolve([s.boundary_object], building.zones, "zone")[0]
            nodes = _add_element(asm, kind, name, room_state, layout, s.area, s.zone, inside_g)
            mirror = _INSIDE_GAMMA.get(_MIRROR.get(s.surface_type, "Wall"), IW)
            asm.link(nodes[0], room_state[other_zone], s.area, mirror)
            face(s, s.zone, nodes[-1])
            other_faces.setdefault(other_zone, []).append((nodes[0], s.area))  # mirrored face
        elif s.boundary == "Outdoors":
            film = roof_film if s.surface_type == "Roof" else None
            nodes = _add_element(asm, kind, name, room_state, layout, s.area, s.zone, inside_g,
                                 film)
            face(s, s.zone, nodes[-1])
            envelope.append((s.zone, nodes[-1], s.area))
            roof = s.surface_type == "Roof"
            if roof and opts.roof_exterior == "idf":  # the roof's own film, known
                asm.to_temperature(nodes[0], 0, ROOF_FILM * s.area, -1)
            elif roof and opts.roof_exterior in ("climate", "balance"):  # the site's wind
                conv, lw = climate[name]
                # with a sky model, the long-wave's sky share goes to the sky (below)
                to_air = conv + lw * (1.0 - sky_share(s.tilt) if roof_sky != "none" else 1.0)
                asm.to_temperature(nodes[0], 0, to_air * s.area, -1)
            elif roof and own_roof:  # the roofs' own film, fitted
                asm.to_temperature(nodes[0], 0, s.area, ROOF)
            else:
                asm.to_temperature(nodes[0], 0, s.area, EW)  # paper eq:q_bh, convection
            known = roof and opts.roof_exterior in ("idf", "absorptance", "climate", "own",
                                                    "balance")
            absorp = outer_absorptance(cons) if known else 1.0  # else gamma_absorp's
            for col, w in facade_of(s.tilt, s.azimuth, opts.roof_solar, rotation).items():
                asm.source(nodes[0], DISTURBANCES.index(col), w * absorp * s.area,
                           -1 if known else ABSORP)
            view = sky_share(s.tilt)
            h_sky, sky = SKY_RADIATION, opts.sky
            if roof and opts.roof_exterior in ("climate", "balance"):
                # the face's own long-wave coefficient; none for SimpleCombined, whose
                # combined film EnergyPlus links to the air alone
                h_sky, sky = climate[name][1], roof_sky
            if sky != "none" and view > 1e-6 and h_sky > 0:
                # long-wave to the sky: a scheduled input of constant "airflow"
                # h_sky F A / c_p at the outer face whose supply is the sky temperature
                box = f"sky:{name}"
                ground_boxes[box] = (s.zone, nodes[0])
                box_rooms[box] = s.zone
                scheduled[box] = {"flow": h_sky * view * s.area / opts.cp_air,
                                  "supply": "sky", "sky": sky}
            area_ext += s.area
        else:
            nodes = _add_element(asm, kind, name, room_state, layout, s.area, s.zone, inside_g)
            face(s, s.zone, nodes[-1])
            if s.boundary == "Ground":
                envelope.append((s.zone, nodes[-1], s.area))
            if s.boundary == "Ground" and opts.ground == "idf":
                # the outer face held near the ground temperature T_g(month): a scheduled
                # input of constant "airflow" G A / c_p at the face whose supply is T_g
                box = f"ground:{name}"
                ground_boxes[box] = (s.zone, nodes[0])
                box_rooms[box] = s.zone
                scheduled[box] = {"flow": GROUND_CONDUCTANCE * s.area / opts.cp_air,
                                  "supply": "ground",
                                  "monthly": [float(t)
                                              for t in building.ground_temperature_at(name)]}
            elif s.boundary == "Adiabatic" and opts.adiabatic == "mirror":
                _mirror(asm, nodes)
                n_mirror += 1
            elif s.boundary not in ("Adiabatic", "Ground"):
                notes.append(f"surface {name}: boundary {s.boundary} treated as adiabatic")
    if n_mirror:
        notes.append(f"{n_mirror} adiabatic surfaces: outer face held at the inner face's "
                     "temperature, as EnergyPlus does (ModelOptions.adiabatic)")
    if any(s.boundary == "Ground" for s in surfaces.values()):
        notes.append("ground-contact surfaces: outer face adiabatic (ModelOptions.ground)"
                     if opts.ground == "adiabatic" else
                     "ground-contact surfaces: outer face at the IDF's monthly ground "
                     "temperature (scheduled inputs)")

    for name in sorted(building.internal_masses):
        m = building.internal_masses[name]
        layout = layout_of(building.constructions[m.construction])
        nodes = _add_element(asm, "internal_mass", name, room_state, layout, m.area, m.zone, IW)
        if opts.internal_mass == "one_face":
            # EnergyPlus's internal mass is its own other side (ExtBoundCond = itself, as an
            # adiabatic surface): one face of the given area meets the zone, the back face is
            # held as an Adiabatic surface's (docs/model.md "States")
            if opts.adiabatic == "mirror":
                _mirror(asm, nodes)
            other_faces.setdefault(m.zone, []).append((nodes[-1], m.area))
        else:
            # both faces of the given area exposed to the zone
            asm.link(nodes[0], room_state[m.zone], m.area, IW)
            other_faces.setdefault(m.zone, []).extend([(nodes[0], m.area), (nodes[-1], m.area)])

    if opts.envelope_radiation == "room":
        n_env = _envelope_radiation(asm, envelope, room_state, floor_faces, other_faces)
        notes.append(f"envelope faces' long-wave exchange with their rooms: {n_env} faces "
                     f"({INTERIOR_RADIATION} W/m2K in series with {ROOM_FACE_CONVECTION} "
                     "W/m2K at the room's other faces)")

    enclosure = (solar_enclosures(building.air_boundaries)
                 if opts.solar_enclosure == "air_boundaries" else {})
    for members in sorted({tuple(m) for m in enclosure.values()}):
        notes.append("one solar enclosure (air boundaries): the sun through the windows of "
                     + ", ".join(members) + " lands on the faces of all of them")
    window_area: dict[str, np.ndarray] = {}
    glass_faces: dict[str, list[tuple[int, float]]] = {}
    rated = [(w.u_value, w.area) for w in building.windows.values() if w.u_value]
    u_nominal = (sum(u * a for u, a in rated) / sum(a for _, a in rated)) if rated \
        else WINDOW_U_DEFAULT
    shaded: list[tuple[str, int, float, np.ndarray, list[np.ndarray]]] = []
    interior_glass: dict[frozenset, dict[str, float]] = {}
    rooms_of_pair: dict[frozenset, tuple[int, int]] = {}
    for name in sorted(building.windows):
        w = building.windows[name]
        parent = surfaces[w.surface]
        r = room_state[w.zone]
        if parent.boundary == "Outdoors":
            if opts.interior_radiation == "star":
                # the glass as a node: convection to the air (gamma_IW), long-wave with the
                # room's faces (the star), U_win scaled to glass + outside film to outdoors
                node = asm.add_state(StateLabel("window", w.zone, name, 0),
                                     GLASS_CAPACITY * w.area)
                asm.link(node, r, w.area, IW)
                asm.to_temperature(node, 0, w.area * glass_factor(w.u_value or u_nominal),
                                   UWIN)
                glass_faces.setdefault(w.zone, []).append((node, w.area))
            else:
                asm.to_temperature(r, 0, w.area, UWIN)  # paper eq:q_bh, window transmission
            members = enclosure.get(w.zone, [w.zone])
            targets = _solar_targets(opts, [f for m in members for f in floor_faces.get(m, [])],
                                     [f for m in members for f in other_faces.get(m, [])], r)
            cols = facade_of(parent.tilt, parent.azimuth, opts.roof_solar, rotation)
            shades = (building.shading.get(name, []) + building.shading.get("*", [])
                      if opts.shading == "idf" else [])
            facade_cols = {c: wt for c, wt in cols.items() if c in _FACADES.values()}
            if shades and len(cols) == 1 and facade_cols and w.vertices is not None:
                shaded.append((name, DISTURBANCES.index(next(iter(cols))) - 2, w.area,
                               w.vertices, shades))
            elif shades:
                notes.append(f"window {name}: not vertical, its shading is not modelled")
            for col, wt in facade_cols.items():  # the facades' window areas
                seen_area = window_area.setdefault(w.zone, np.zeros(4))
                seen_area[DISTURBANCES.index(col) - 2] += wt * w.area
            for col, wt in cols.items():
                for node, share in targets:
                    asm.source(node, DISTURBANCES.index(col), wt * w.area * share, WINSOL)
            area_win += w.area
        elif parent.boundary == "Surface":
            other = surfaces[skey[parent.boundary_object.lower()]]
            # an interzone window is listed on both walls of the pair (EnergyPlus requires
            # it), or on one when EnergyPlus made the far side: one coupling per wall pair,
            # of the larger side's glass area
            side = interior_glass.setdefault(frozenset((parent.name, other.name)), {})
            side[parent.name] = side.get(parent.name, 0.0) + w.area
            rooms_of_pair[frozenset((parent.name, other.name))] = (r, room_state[other.zone])
            notes.append(f"interior window {name}: U_win coupling between rooms")
        else:
            notes.append(f"window {name} on a {parent.boundary} surface: ignored")
    for pair, side in interior_glass.items():
        ra, rb = rooms_of_pair[pair]
        asm.link(ra, rb, max(side.values()), UWIN)
    shading = _window_shading(shaded, window_area, notes)
    if opts.interior_radiation == "star":
        for room, faces in glass_faces.items():
            other_faces.setdefault(room, []).extend(faces)  # after the solar targets
        n_links = _interior_radiation(asm, floor_faces, other_faces)
        notes.append(f"interior long-wave exchange: {n_links} face-to-face links "
                     f"({INTERIOR_RADIATION} W/m2K star network; windows' glass as nodes)")
    if opts.infiltration == "idf":
        for name in sorted(building.infiltration):
            inf = building.infiltration[name]
            if inf.flow <= 0 or inf.zone not in room_state:
                continue
            if inf.schedule:
                # a scheduled input: a box whose airflow follows the schedule and whose
                # supply air is the outdoor air (rho q F(t) c_p (v_Ta - x_room))
                box = f"infiltration:{name}"
                box_rooms[box] = inf.zone
                scheduled[box] = {"flow": opts.rho_air * inf.flow, "supply": "Ta",
                                  "schedule": building.schedules[inf.schedule].to_dict()}
                notes.append(f"infiltration {name}: follows schedule {inf.schedule} "
                             "(a scheduled input)")
            else:
                # outdoor air at v_Ta replacing room air: rho c_p q (v_Ta - x_room), fixed
                asm.to_temperature(room_state[inf.zone], 0,
                                   opts.rho_air * opts.cp_air * inf.flow, -1)


    for a, b, flow in building.air_boundaries:
        if flow > 0 and a in room_state and b in room_state:
            # an open boundary (Construction:AirBoundary): EnergyPlus's cross mixing,
            # rho c_p q (x_b - x_a) both ways, fixed
            asm.link(room_state[a], room_state[b], opts.rho_air * opts.cp_air * flow, -1)
            notes.append(f"air boundary {a} - {b}: mixing {flow:.4g} m3/s")

    return_of_box = None
    if opts.return_air == "idf" and building.return_plenum:
        ret = [room_state.get(building.return_plenum.get(box_rooms[b], ""), -1)
               if b not in scheduled else -1 for b in box_rooms]
        if any(r >= 0 for r in ret):
            return_of_box = np.array(ret, dtype=int)
            plen = sorted({building.return_plenum[box_rooms[b]] for b, r in zip(box_rooms, ret)
                           if r >= 0})
            notes.append(f"return air of {sum(r >= 0 for r in ret)} boxes into the plenum(s) "
                         f"{', '.join(plen)}: c_p u (x_room - x_plenum)")
    cap, a_list, b_list = asm.matrices()
    n = len(cap)
    switched = _regime_links(asm, room_state, box_rooms, scheduled, notes) \
        if opts.inside_convection == "regime" else {}
    zone_names = list(zone_rooms)
    b_ig = np.zeros((n, len(zone_names)))
    c_mat = np.zeros((len(zone_names), n))
    glass: dict[str, float] = {}  # window area without a node (its radiant share: the air)
    for w in building.windows.values():
        if opts.interior_radiation != "star" or surfaces[w.surface].boundary != "Outdoors":
            glass[w.zone] = glass.get(w.zone, 0.0) + w.area
    n_split = 0
    for zi, z in enumerate(zone_names):
        vols = np.array([building.zones[r].volume for r in zone_rooms[z]])
        for r, vol in zip(zone_rooms[z], vols):
            i = room_state[r]
            heat = building.zones[r].floor_area  # paper eq:q_ig: a_floor (c_IG + f_IG)
            if opts.internal_gains == "idf":
                # the radiant share reaches the faces of the room's solar enclosure
                members = enclosure.get(r, [r])
                targets = _gain_targets(building, r, room_state,
                                        [f for m in members for f in floor_faces.get(m, [])],
                                        [f for m in members for f in other_faces.get(m, [])],
                                        sum(glass.get(m, 0.0) for m in members))
                n_split += len(targets) > 1
            else:
                targets = [(i, 1.0)]
            for node, share in targets:
                b_ig[node, zi] += heat * share / cap[node]
            c_mat[zi, i] = vol / vols.sum()  # volume-weighted mean of the zone's rooms
    if opts.internal_gains == "idf":
        notes.append(f"internal gains of {n_split} rooms split as the IDF's People, Lights and "
                     "equipment: convective on the air, radiant on the inside faces, "
                     "return-air share in the return plenum")
    return RCStructure(
        labels=asm.labels,
        rooms=rooms,
        zones=zone_rooms,
        boxes=box_rooms,
        capacity=cap,
        A0=a_list[0],
        A_p=a_list[1:],
        Bv0=b_list[0],
        Bv_p=b_list[1:],
        B_ig=b_ig,
        room_of_box=np.array([ground_boxes[b][1] if b in ground_boxes
                              else room_state[box_rooms[b]] for b in box_rooms], dtype=int),
        return_of_box=return_of_box,
        C=c_mat,
        cp_air=opts.cp_air,
        notes=notes,
        areas={"exterior_opaque": area_ext, "windows": area_win},
        window_area=window_area,
        options=opts,
        facade_rotation=rotation,
        scheduled=scheduled,
        shading=shading,
        window_panes=(1 if u_nominal >= SINGLE_PANE_U else 2)
        if opts.window_angle == "glass" else 0,
        switched=switched,
        extra_params=("gamma_roof",) if own_roof else (),
    )


def _regime_links(asm: _Assembler, room_state: Mapping[str, int], box_rooms: Mapping[str, str],
                  scheduled: Mapping[str, dict], notes: list[str]) -> dict:
    """:attr:`RCStructure.switched` of ``inside_convection="regime"``: every floor or
    ceiling film (parameter γ_floor or γ_ceil) between a face and the air of a room with VAV
    boxes, with Walton's regime ratio for that face (:data:`REGIME_FLOOR`,
    :data:`REGIME_CEILING`)."""
    rooms = sorted({box_rooms[b] for b in box_rooms if b not in scheduled})
    col = {room_state[r]: i for i, r in enumerate(rooms)}
    links, area, param, factor = [], [], [], []
    for i, j, g, p in asm.links:
        if p not in (FLOOR, CEIL):
            continue
        face, air = (i, j) if j in col else (j, i)
        if air not in col:
            continue
        links.append((face, air, col[air]))
        area.append(g)
        param.append(p)
        factor.append(REGIME_FLOOR if p == FLOOR else REGIME_CEILING)
    if not links:
        return {}
    notes.append(f"inside convection regimes: {len(links)} floor/ceiling films of "
                 f"{len(rooms)} rooms switched while their boxes reheat (floor x"
                 f"{REGIME_FLOOR:g}, ceiling x{REGIME_CEILING:g})")
    return {"links": np.array(links, dtype=np.int64), "area": np.array(area),
            "param": np.array(param, dtype=np.int64), "factor": np.array(factor),
            "rooms": rooms}
