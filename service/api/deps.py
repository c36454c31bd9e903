"""Dependencies of the routes as ``Annotated`` types: the service context (``Ctx``), the
bearer-token check with the token's scopes (``PrincipalDep``), the building's runner
(``RunnerDep``) and the building id path parameter (``BuildingId``); plus the dependency
lists and error answers of the protected routers.

Scopes (docs/security.md): ``admin`` may do everything; ``building:<id>`` reads and writes
the routes of building ``<id>`` (every ``/api/v1/buildings/{building_id}/...``),
``building:<id>:read`` only reads them (GET); ``metrics`` reads ``/metrics``. A token
without the scope a route needs gets 403; ``GET /api/v1/buildings`` lists only the
buildings the token may read.

The dependencies are coroutines: they do not block (no storage, no lock), and FastAPI runs a
plain ``def`` in the thread pool, a thread hand-off per dependency and request.
"""

from __future__ import annotations

import hmac
from dataclasses import dataclass
from typing import Annotated, Any

from fastapi import Depends, HTTPException, Path, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from zonecast.service import schemas as S
from zonecast.service.context import ServiceContext
from zonecast.service.runner import Runner

__all__ = ["AUTH", "ERRORS", "METRICS_AUTH", "BuildingId", "Ctx", "Principal", "PrincipalDep",
           "RunnerDep", "get_ctx", "get_runner", "require_building_scope",
           "require_metrics_scope", "require_token"]

BuildingId = Annotated[str, Path(pattern=r"^[A-Za-z0-9_-]{1,64}$",
                                 description="building identifier")]

_bearer = HTTPBearer(auto_error=False, description="API token from the service settings")


async def get_ctx(request: Request) -> ServiceContext:
    return request.app.state.zc


Ctx = Annotated[ServiceContext, Depends(get_ctx)]


@dataclass(frozen=True)
class Principal:
    """What the request's token may do: its scopes (``ServiceSettings.api_tokens``)."""

    scopes: frozenset[str]

    @property
    def admin(self) -> bool:
        return "admin" in self.scopes

    def can_read(self, building: str) -> bool:
        """GET routes of ``building``."""
        return self.admin or bool({f"building:{building}", f"building:{building}:read"}
                                  & self.scopes)

    def can_write(self, building: str) -> bool:
        """Routes of ``building`` that change something (telemetry POST)."""
        return self.admin or f"building:{building}" in self.scopes

    def can_scrape(self) -> bool:
        """``/metrics`` (counters of every building)."""
        return self.admin or "metrics" in self.scopes


async def require_token(ctx: Ctx, cred: Annotated[HTTPAuthorizationCredentials | None,
                                             Depends(_bearer)]) -> Principal:
    """Bearer-token check: the given token is compared with every configured one by
    ``hmac.compare_digest`` (no early exit); 401 if none matches."""
    challenge = {"WWW-Authenticate": "Bearer"}
    if cred is None:
        raise HTTPException(401, "missing bearer token: send 'Authorization: Bearer <token>'",
                            headers=challenge)
    given = cred.credentials.encode()
    scopes: tuple[str, ...] | None = None
    for token, token_scopes in ctx.settings.api_tokens.items():
        if hmac.compare_digest(given, token.get_secret_value().encode()):
            scopes = token_scopes
    if scopes is None:
        raise HTTPException(401, "invalid bearer token" if ctx.settings.api_tokens else
                            "no API tokens are configured (settings api_tokens)",
                            headers=challenge)
    return Principal(frozenset(scopes))


PrincipalDep = Annotated[Principal, Depends(require_token)]


async def require_building_scope(request: Request, principal: PrincipalDep) -> Principal:
    """The token check, and for a route with a ``building_id`` path parameter its scope:
    reading needs ``building:<id>[:read]``, any other method ``building:<id>`` (or
    ``admin``); 403 otherwise. The building need not exist (403 before 404, so a token
    learns nothing about other buildings)."""
    bid = request.path_params.get("building_id")
    if bid is None:
        return principal
    if request.method in ("GET", "HEAD"):
        if not principal.can_read(bid):
            raise HTTPException(403, f"this token may not read building {bid!r}: it needs "
                                     f"scope 'building:{bid}', 'building:{bid}:read' or "
                                     "'admin'")
    elif not principal.can_write(bid):
        raise HTTPException(403, f"this token may not write to building {bid!r}: it needs "
                                 f"scope 'building:{bid}' or 'admin'")
    return principal


async def require_metrics_scope(principal: PrincipalDep) -> Principal:
    """``/metrics`` needs scope ``metrics`` or ``admin`` (it counts every building)."""
    if not principal.can_scrape():
        raise HTTPException(403, "this token may not read /metrics: it needs scope 'metrics' "
                                 "or 'admin'")
    return principal


async def read_body(request: Request, limit: int) -> bytes:
    """The request body, refused with 413 when its declared or actual size exceeds
    ``limit`` [bytes] (the service's ``max_body_bytes``) before more is read."""
    declared = request.headers.get("content-length")
    if declared is not None and declared.isdigit() and int(declared) > limit:
        raise HTTPException(413, f"body is {declared} bytes, the limit is {limit}")
    body = await request.body()
    if len(body) > limit:
        raise HTTPException(413, f"body is {len(body)} bytes, the limit is {limit}")
    return body


async def get_runner(ctx: Ctx, building_id: BuildingId, principal: PrincipalDep) -> Runner:
    """The runner of ``building_id``; 404 naming the known buildings the token may read,
    or the reason its model did not load."""
    runner = ctx.runners.get(building_id)
    if runner is None:
        if building_id in ctx.load_errors:
            raise HTTPException(404, f"building {building_id!r} is configured but its model "
                                     f"did not load: {ctx.load_errors[building_id]}")
        raise HTTPException(404, f"unknown building {building_id!r}; known: "
                                 f"{sorted(b for b in ctx.runners if principal.can_read(b))}")
    return runner


RunnerDep = Annotated[Runner, Depends(get_runner)]

#: dependencies of every protected router under /api/v1: token and building scope
AUTH = [Depends(require_building_scope)]
#: dependencies of /metrics: token and scope ``metrics``
METRICS_AUTH = [Depends(require_metrics_scope)]
#: answers of the protected routers besides 200: the token check (401), its scope (403),
#: the building look-up (404) and invalid parameters (422)
ERRORS: dict[int | str, dict[str, Any]] = {401: {"model": S.ErrorBody},
                                           403: {"model": S.ErrorBody},
                                           404: {"model": S.ErrorBody},
                                           422: {"model": S.ErrorBody}}
