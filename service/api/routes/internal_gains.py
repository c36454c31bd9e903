"""``/api/v1/buildings/{building_id}/internal-gains``: online internal gains and the weekly
profile."""

from __future__ import annotations

import numpy as np
from fastapi import APIRouter
from zonecast.service import schemas as S
from zonecast.service.api.deps import AUTH, ERRORS, BuildingId, RunnerDep
from zonecast.service.bodies import as_utc, finite_or_none

router = APIRouter(prefix="/buildings", tags=["internal-gains"], dependencies=AUTH,
                   responses=ERRORS)


@router.get("/{building_id}/internal-gains", response_model=S.InternalGains,
            summary="Online internal gains and the weekly profile")
def get_gains(building_id: BuildingId, runner: RunnerDep):
    b = runner.bundle
    with runner.lock:
        online, last, t = runner.est.online_gains, runner.est.last_f, runner.est.time
    prof = np.nan_to_num(b.profile.values)
    zones = [S.ZoneGains(zone=z, online=float(online[i]), last_estimate=finite_or_none(last[i]),
                         profile=prof[:, i].tolist()) for i, z in enumerate(b.zones)]
    return S.InternalGains(building=building_id, time=as_utc(t),
                           profile_timezone=b.profile.timezone, zones=zones)
