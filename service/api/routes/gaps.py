"""``/api/v1/buildings/{building_id}/gaps``: gaps in the telemetry the site declares, paged.

The runner finds gaps as it closes rows (``service/gaps.py``) and stores them; this route
reads them with one range query on the ``gaps`` table (its key starts with the building and
the gap's start), never the readings.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query
from pydantic import AwareDatetime
from zonecast.service import schemas as S
from zonecast.service.api.deps import AUTH, ERRORS, BuildingId, Ctx, RunnerDep
from zonecast.service.bodies import as_utc
from zonecast.service.storage import Gap

router = APIRouter(prefix="/buildings", tags=["gaps"], dependencies=AUTH, responses=ERRORS)

#: most items in one page
MAX_LIMIT = 1000


def _item(gap: Gap, position) -> S.GapItem:
    end = position if gap.open and position is not None else gap.end
    steps = int((end - gap.start).total_seconds() // 900)
    return S.GapItem(point=gap.point, start=as_utc(gap.start), end=as_utc(end), steps=steps,
                     open=gap.open)


@router.get("/{building_id}/gaps", response_model=S.GapPage,
            summary="Gaps in the telemetry: per point, steps closed without a reading")
def get_gaps(ctx: Ctx, building_id: BuildingId, runner: RunnerDep,
             start: Annotated[AwareDatetime | None, Query(
                 alias="from", description="only gaps that end after this time (ISO-8601 "
                 "with offset)")] = None,
             end: Annotated[AwareDatetime | None, Query(
                 alias="to", description="only gaps that start before this time (ISO-8601 "
                 "with offset)")] = None,
             point: Annotated[str | None, Query(max_length=256,
                                                description="only this point")] = None,
             open_only: Annotated[bool, Query(alias="open",
                                              description="only gaps still open")] = False,
             limit: Annotated[int, Query(ge=1, le=MAX_LIMIT,
                                         description="items per page")] = 100,
             offset: Annotated[int, Query(ge=0, description="items to skip")] = 0):
    if start is not None and end is not None and end <= start:
        raise ValueError(f"'to' ({end.isoformat()}) must be after 'from' "
                         f"({start.isoformat()})")
    tracker = runner.gaps
    position = tracker.position
    total, page = ctx.storage.gaps(building_id, start, end, point=point, open_only=open_only,
                                   limit=limit, offset=offset)
    following = offset + len(page)
    return S.GapPage(building=building_id, total=total, offset=offset,
                     next_offset=following if following < total else None,
                     tolerance_s=tracker.tolerance, position=as_utc(position),
                     items=[_item(g, position) for g in page])
