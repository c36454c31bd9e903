"""Property-based requests generated from the OpenAPI spec (schemathesis): no 5xx.

Bounded: at most 15 generated cases per operation (about 20 s in all). The service runs
with its lifespan (storage, model, runner) and a few stored steps, so the state and
forecast endpoints answer with data.
"""

from __future__ import annotations

import time

import pytest
import schemathesis
from hypothesis import HealthCheck, given, settings
from schemathesis.checks import not_a_server_error
from test_service_app import AUTH, body_of, make_settings


@pytest.fixture(scope="module")
def api_schema(tmp_path_factory, vb, telemetry):
    from fastapi.testclient import TestClient
    from zonecast.service.app import create_app

    tmp = tmp_path_factory.mktemp("fuzz")
    app = create_app(make_settings(tmp, vb, forecast_every=4))
    with TestClient(app) as client:
        for i in range(5):
            client.post("/api/v1/buildings/office6/telemetry", json=body_of(telemetry.iloc[i]),
                        headers=AUTH)
        deadline = time.monotonic() + 30
        while app.state.zc.runners["office6"].forecast is None and time.monotonic() < deadline:
            time.sleep(0.05)
        yield schemathesis.openapi.from_asgi("/openapi.json", app)


def test_no_server_error(api_schema):
    """Every operation, with and without the token (schemathesis's pytest plugin does not
    work with this pytest; the strategies are driven with hypothesis directly)."""
    operations = [result.ok() for result in api_schema.get_all_operations()]
    assert len(operations) == 15  # + gaps, history, health, diagnosis, weather forecast (2)

    for op in operations:
        @given(case=op.as_strategy())
        @settings(max_examples=15, deadline=None, database=None,
                  suppress_health_check=list(HealthCheck))
        def check(case):
            case.call_and_validate(headers=AUTH, checks=[not_a_server_error])
            case.call_and_validate(checks=[not_a_server_error])  # no token: 401, never 5xx

        check()
