"""``/api/v1/buildings``: the served buildings and their models."""

from __future__ import annotations

from fastapi import APIRouter
from zonecast.service import schemas as S
from zonecast.service.api.deps import AUTH, ERRORS, BuildingId, Ctx, PrincipalDep, RunnerDep
from zonecast.service.bodies import as_utc
from zonecast.service.runner import Runner

router = APIRouter(prefix="/buildings", tags=["buildings"], dependencies=AUTH,
                   responses=ERRORS)


def _summary(bid: str, runner: Runner) -> S.BuildingSummary:
    return S.BuildingSummary(id=bid, zones=runner.bundle.zones,
                             model_version=runner.bundle.version,
                             last_update=as_utc(runner.est.time))


@router.get("", response_model=list[S.BuildingSummary], summary="List buildings",
            description="The buildings the token may read (all of them for scope admin).")
def list_buildings(ctx: Ctx, principal: PrincipalDep):
    return [_summary(bid, r) for bid, r in sorted(ctx.runners.items())
            if principal.can_read(bid)]


@router.get("/{building_id}", response_model=S.BuildingDetail, summary="One building")
def get_building(building_id: BuildingId, runner: RunnerDep):
    b = runner.bundle
    site = b.site
    return S.BuildingDetail(
        **_summary(building_id, runner).model_dump(), timezone=site.timezone,
        latitude=site.location.latitude, longitude=site.location.longitude,
        step_s=site.step.total_seconds(), n_states=b.model.n, boxes=list(site.boxes),
        points=dict(site.point_units()),
        parameters=dict(zip(b.model.params.param_names, map(float, b.model.params.values))),
        notes=b.notes)
