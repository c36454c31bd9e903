"""REST token scopes (docs/security.md): ``admin``, ``metrics``, ``building:<id>`` and
``building:<id>:read``, on every route family, and the settings forms that configure them.

Two buildings, ``office6`` and ``office7``, served from the same virtual-building model file.
"""

from __future__ import annotations

import hmac

import pandas as pd
import pytest

ADMIN = "admin-token-0123456789"
OWN6 = "office6-token-0123456789"  # building:office6 (read and write)
READ6 = "office6-read-0123456789"  # building:office6:read
SCRAPE = "metrics-token-0123456789"  # metrics
BUILDING_GETS = ["", "/state", "/internal-gains", "/forecast"]


def bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


def body_of(row: pd.Series) -> dict:
    return {"time": row["time"],
            "readings": {k: float(v) for k, v in row.items() if k != "time" and pd.notna(v)}}


@pytest.fixture
def client(tmp_path, vb):
    from fastapi.testclient import TestClient
    from zonecast.service.app import create_app
    from zonecast.service.settings import load_settings

    settings = load_settings(
        storage_url=f"sqlite:///{tmp_path / 'zc.db'}", mqtt_enabled=False,
        buildings={"office6": str(vb / "model.json"), "office7": str(vb / "model.json")},
        api_tokens={ADMIN: ["admin"], OWN6: ["building:office6"],
                    READ6: ["building:office6:read"], SCRAPE: "metrics"},
        runner={"poll_interval": 0.05, "publish": False})
    with TestClient(create_app(settings)) as c:
        yield c


def test_building_token_reads_its_building_like_admin_and_nothing_else(client):
    for suffix in BUILDING_GETS:
        own = f"/api/v1/buildings/office6{suffix}"
        want = client.get(own, headers=bearer(ADMIN))
        assert want.status_code in (200, 409), (own, want.text)  # 409: forecast before data
        for token in (OWN6, READ6):
            got = client.get(own, headers=bearer(token))
            assert (got.status_code, got.json()) == (want.status_code, want.json()), own
        other = f"/api/v1/buildings/office7{suffix}"
        assert client.get(other, headers=bearer(ADMIN)).status_code in (200, 409)
        for token in (OWN6, READ6, SCRAPE):
            r = client.get(other, headers=bearer(token))
            assert r.status_code == 403, (other, r.text)
            assert "building:office7" in r.json()["detail"]


def test_building_list_shows_only_what_the_token_may_read(client):
    def ids(token):
        r = client.get("/api/v1/buildings", headers=bearer(token))
        assert r.status_code == 200, r.text
        return [b["id"] for b in r.json()]

    assert ids(ADMIN) == ["office6", "office7"]
    assert ids(OWN6) == ids(READ6) == ["office6"]
    assert ids(SCRAPE) == []


def test_unknown_building_is_403_for_a_scoped_token_and_404_for_admin(client):
    """A scoped token learns nothing about other building ids (403 before the look-up);
    admin's 404 names the known buildings."""
    r = client.get("/api/v1/buildings/nope/state", headers=bearer(OWN6))
    assert r.status_code == 403 and "office7" not in r.text
    r = client.get("/api/v1/buildings/nope/state", headers=bearer(ADMIN))
    assert r.status_code == 404 and "office6" in r.json()["detail"]


def stored(client, building: str) -> int:
    """Number of readings stored for ``building``."""
    frame = client.app.state.zc.storage.readings(building, "2000-01-01T00:00:00Z",
                                                 "2100-01-01T00:00:00Z")
    return int(frame.notna().to_numpy().sum())


def test_telemetry_write_needs_the_read_write_scope_of_that_building(client, telemetry):
    row = body_of(telemetry.iloc[0])
    r = client.post("/api/v1/buildings/office6/telemetry", json=row, headers=bearer(READ6))
    assert r.status_code == 403 and "may not write" in r.json()["detail"]
    r = client.post("/api/v1/buildings/office7/telemetry", json=row, headers=bearer(OWN6))
    assert r.status_code == 403 and "building:office7" in r.json()["detail"]
    r = client.post("/api/v1/buildings/office7/telemetry", json=row, headers=bearer(SCRAPE))
    assert r.status_code == 403
    # nothing of the refused posts was stored
    assert stored(client, "office6") == stored(client, "office7") == 0
    r = client.post("/api/v1/buildings/office6/telemetry", json=row, headers=bearer(OWN6))
    assert r.status_code == 200 and r.json()["stored"] == len(row["readings"]), r.text
    r = client.post("/api/v1/buildings/office7/telemetry", json=row, headers=bearer(ADMIN))
    assert r.status_code == 200 and r.json()["stored"] == len(row["readings"]), r.text
    assert stored(client, "office6") == stored(client, "office7") == len(row["readings"])


def test_metrics_needs_scope_metrics_or_admin(client):
    for token in (ADMIN, SCRAPE):
        r = client.get("/metrics", headers=bearer(token))
        assert r.status_code == 200 and "zonecast_messages_total" in r.text
    for token in (OWN6, READ6):
        r = client.get("/metrics", headers=bearer(token))
        assert r.status_code == 403 and "scope 'metrics'" in r.json()["detail"]
    assert client.get("/metrics", headers=bearer("not-a-token-0123")).status_code == 401


def test_every_configured_token_is_compared_in_constant_time(client, monkeypatch):
    """The given token is compared with every configured token by hmac.compare_digest (no
    early exit at the first match)."""
    from zonecast.service.api import deps

    calls = []
    compare = hmac.compare_digest

    def counting(a, b):
        calls.append(1)
        return compare(a, b)

    monkeypatch.setattr(deps.hmac, "compare_digest", counting)
    assert client.get("/api/v1/buildings", headers=bearer(ADMIN)).status_code == 200
    assert len(calls) == 4  # ADMIN is the first of four tokens


# --------------------------------------------------------------------------- settings forms
def test_token_list_form_means_admin_and_mapping_form_takes_scopes(monkeypatch):
    from zonecast.service.settings import load_settings

    s = load_settings(api_tokens=["legacy-token-1"], buildings={"office6": "m.json"})
    assert {t.get_secret_value(): v for t, v in s.api_tokens.items()} == \
        {"legacy-token-1": ("admin",)}
    monkeypatch.setenv("ZONECAST_API_TOKENS",
                       '{"tok-a-0123456789": ["building:office6:read", "metrics"], '
                       '"tok-b-0123456789": "admin"}')
    s = load_settings(buildings={"office6": "m.json"})
    assert {t.get_secret_value(): v for t, v in s.api_tokens.items()} == \
        {"tok-a-0123456789": ("building:office6:read", "metrics"),
         "tok-b-0123456789": ("admin",)}
    assert "0123456789" not in repr(s)


@pytest.mark.parametrize("tokens,match", [
    ({"tok-0123456789": ["owner"]}, "unknown scope 'owner'"),
    ({"tok-0123456789": ["building:office6:write"]}, "unknown scope"),
    ({"tok-0123456789": []}, "has no scope"),
    ({"tok-0123456789": ["building:office9"]}, "names no configured building"),
    ({" tok-0123456789\n": ["admin"]}, "surrounding whitespace"),
    ({"": ["admin"]}, "empty"),
])
def test_bad_token_settings_say_what_to_fix(tokens, match):
    from zonecast.service.settings import load_settings

    with pytest.raises(ValueError, match=match):
        load_settings(api_tokens=tokens, buildings={"office6": "m.json"})
