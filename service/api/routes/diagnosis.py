"""``/api/v1/buildings/{building_id}/diagnosis``: the latest sim-to-real diagnosis of a
building, read from the ``diagnosis.json`` of ``zonecast diagnose`` named in the settings
(``diagnoses``); the service runs no diagnosis itself (read-only)."""

from __future__ import annotations

import json
from datetime import UTC, datetime
from pathlib import Path

from fastapi import APIRouter
from zonecast.service import schemas as S
from zonecast.service.api.deps import AUTH, ERRORS, BuildingId, Ctx, RunnerDep

router = APIRouter(prefix="/buildings", tags=["diagnosis"], dependencies=AUTH, responses=ERRORS)


def _effect(doc: dict) -> S.DiagnosisEffect:
    return S.DiagnosisEffect(
        effect=str(doc["effect"]), zones=[str(z) for z in doc.get("zones") or []],
        confident=bool(doc["confident"]), score=float(doc["score"]),
        confidence=float(doc["confidence"]),
        heldout_rms_before={str(k): float(v) for k, v in
                            (doc.get("heldout_rms_before") or {}).items()},
        heldout_rms_after={str(k): float(v) for k, v in
                           (doc.get("heldout_rms_after") or {}).items()})


def read_diagnosis(building: str, path: Path | None) -> S.DiagnosisBody:
    """The report at ``path`` as a body; ``available`` false, with the reason, when none is
    configured or it cannot be read (never an error: the page shows the reason)."""
    none = {"building": building, "available": False, "file": None, "modified": None,
            "effects": []}
    if path is None:
        return S.DiagnosisBody(**none, detail="no diagnosis configured for this building "
                               "(settings 'diagnoses': building -> diagnosis.json of "
                               "'zonecast diagnose')")
    try:
        modified = datetime.fromtimestamp(path.stat().st_mtime, UTC)
        doc = json.loads(path.read_text())
        effects = [_effect(e) for e in doc["ranked_effects"]]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        # never the folder: an OSError's text holds the full path
        why = ("not found" if isinstance(exc, FileNotFoundError) else
               f"unreadable ({exc.strerror})" if isinstance(exc, OSError) else
               f"unreadable ({type(exc).__name__}: {str(exc)[:200]})")
        return S.DiagnosisBody(**{**none, "file": path.name},
                               detail=f"diagnosis file {path.name} {why}")
    return S.DiagnosisBody(building=building, available=True, file=path.name,
                           modified=modified, effects=effects, detail=None)


# a plain def: reads a file (FastAPI runs it in the thread pool)
@router.get("/{building_id}/diagnosis", response_model=S.DiagnosisBody,
            summary="Latest sim-to-real diagnosis report, if one is configured")
def get_diagnosis(ctx: Ctx, building_id: BuildingId, runner: RunnerDep):
    return read_diagnosis(building_id, ctx.settings.diagnoses.get(building_id))
