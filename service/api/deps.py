"""Dependencies of the routes as ``Annotated`` types: the service context (``Ctx``), the
bearer-token check, the building's runner (``RunnerDep``) and the building id path
parameter (``BuildingId``); plus the dependency list and error answers of the protected
routers.

The dependencies are coroutines: they do not block (no storage, no lock), and FastAPI runs a
plain ``def`` in the thread pool, a thread hand-off per dependency and request.
"""

from __future__ import annotations

import hmac
from typing import Annotated, Any

from fastapi import Depends, HTTPException, Path, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from zonecast.service import schemas as S
from zonecast.service.context import ServiceContext
from zonecast.service.runner import Runner

__all__ = ["AUTH", "ERRORS", "BuildingId", "Ctx", "RunnerDep", "get_ctx", "get_runner",
           "require_token"]

BuildingId = Annotated[str, Path(pattern=r"^[A-Za-z0-9_-]{1,64}$",
                                 description="building identifier")]

_bearer = HTTPBearer(auto_error=False, description="API token from the service settings")


async def get_ctx(request: Request) -> ServiceContext:
    return request.app.state.zc


Ctx = Annotated[ServiceContext, Depends(get_ctx)]


async def require_token(ctx: Ctx, cred: Annotated[HTTPAuthorizationCredentials | None,
                                             Depends(_bearer)]) -> None:
    """Bearer-token check, constant time per configured token."""
    challenge = {"WWW-Authenticate": "Bearer"}
    if cred is None:
        raise HTTPException(401, "missing bearer token: send 'Authorization: Bearer <token>'",
                            headers=challenge)
    given = cred.credentials.encode()
    ok = False
    for token in ctx.settings.api_tokens:
        ok |= hmac.compare_digest(given, token.get_secret_value().encode())
    if not ok:
        raise HTTPException(401, "invalid bearer token" if ctx.settings.api_tokens else
                            "no API tokens are configured (settings api_tokens)",
                            headers=challenge)


async def get_runner(ctx: Ctx, building_id: BuildingId) -> Runner:
    """The runner of ``building_id``; 404 naming the known buildings, or the reason its
    model did not load."""
    runner = ctx.runners.get(building_id)
    if runner is None:
        if building_id in ctx.load_errors:
            raise HTTPException(404, f"building {building_id!r} is configured but its model "
                                     f"did not load: {ctx.load_errors[building_id]}")
        raise HTTPException(404, f"unknown building {building_id!r}; known: "
                                 f"{sorted(ctx.runners)}")
    return runner


RunnerDep = Annotated[Runner, Depends(get_runner)]

#: dependencies of every protected router
AUTH = [Depends(require_token)]
#: answers of the protected routers besides 200: the token check (401), the building
#: look-up (404) and invalid parameters (422)
ERRORS: dict[int | str, dict[str, Any]] = {401: {"model": S.ErrorBody},
                                           404: {"model": S.ErrorBody},
                                           422: {"model": S.ErrorBody}}
