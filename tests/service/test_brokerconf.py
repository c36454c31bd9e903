"""``zonecast mqtt-config``: Mosquitto password file and ACL (service/brokerconf.py). That
Mosquitto accepts the files is tested in test_mqtt_trust.py."""

from __future__ import annotations

import shutil
import stat
import subprocess

import pytest
from typer.testing import CliRunner
from zonecast.service.brokerconf import (
    acl_text,
    hash_password,
    read_passwd,
    verify_password,
    write_broker_files,
)

from zonecast.cli import app as cli


def test_hash_is_mosquittos_sha512_pbkdf2_format():
    h = hash_password("s3cret", salt=bytes(range(12)))
    kind, iterations, salt, digest = h.split("$")[1:]
    assert (kind, iterations, salt) == ("7", "101", "AAECAwQFBgcICQoL")
    assert len(digest) == 88  # 64 bytes in base64
    assert verify_password("s3cret", h) and not verify_password("s3cret!", h)
    assert hash_password("s3cret") != hash_password("s3cret")  # random salt
    with pytest.raises(ValueError, match="empty"):
        hash_password("")
    with pytest.raises(ValueError, match="not a Mosquitto"):
        verify_password("x", "$6$abc$def")


@pytest.mark.skipif(shutil.which("mosquitto_passwd") is None, reason="mosquitto_passwd not on "
                    "PATH")
def test_hashes_of_mosquitto_passwd_verify_the_same_way(tmp_path):
    """Both directions of the format: mosquitto_passwd's own sha512-pbkdf2 hash is read and
    verified here (that Mosquitto accepts ours is test_mqtt_trust.py)."""
    path = tmp_path / "passwd"
    path.touch()
    subprocess.run(["mosquitto_passwd", "-H", "sha512-pbkdf2", "-b", str(path), "office6",
                    "pa55-word"], check=True, capture_output=True)
    hashed = read_passwd(path)["office6"]
    assert hashed.startswith("$7$101$")
    assert verify_password("pa55-word", hashed) and not verify_password("pa55-wore", hashed)


def test_files_users_modes_and_the_acl(tmp_path):
    res = write_broker_files(["office6", "office7"], tmp_path / "auth")
    assert list(read_passwd(res.passwd)) == ["zonecast", "office6", "office7"]
    for user, password in res.passwords.items():
        assert verify_password(password, read_passwd(res.passwd)[user])
        assert len(password) >= 40
    for path in (res.passwd, res.acl, res.credentials):
        assert stat.S_IMODE(path.stat().st_mode) == 0o600, path
    lines = res.credentials.read_text().splitlines()[1:]
    assert lines == [f"{u} {p}" for u, p in res.passwords.items()]
    acl = res.acl.read_text()
    assert acl == acl_text("zonecast")
    # building users: only their own topics, by pattern; the service user's block
    assert "pattern write zonecast/%u/telemetry" in acl
    assert "user zonecast\ntopic read zonecast/+/telemetry" in acl
    assert "topic write zonecast/+/forecast" in acl.split("user zonecast")[1]
    assert not any(line.startswith("topic") for line in acl.split("user zonecast")[0]
                   .splitlines()), "a topic line before 'user' would apply to anonymous clients"


def test_rerun_keeps_passwords_adds_buildings_and_rotates_on_request(tmp_path):
    out = tmp_path / "auth"
    first = write_broker_files(["office6"], out)
    before = read_passwd(first.passwd)
    first.credentials.unlink()  # handed out
    second = write_broker_files(["office6", "office7"], out, rotate=["office6"])
    after = read_passwd(second.passwd)
    assert after["zonecast"] == before["zonecast"] and second.kept == ["zonecast"]
    assert after["office6"] != before["office6"]
    assert set(second.passwords) == {"office6", "office7"}
    with pytest.raises(ValueError, match="still holds passwords"):
        write_broker_files(["office6", "office7", "office8"], out)
    assert read_passwd(second.passwd) == after  # nothing changed
    second.credentials.unlink()
    third = write_broker_files(["office7"], out)  # office6 removed, nothing new
    assert list(read_passwd(third.passwd)) == ["zonecast", "office7"]
    assert third.credentials is None and third.passwords == {}


@pytest.mark.parametrize("kwargs,match", [
    ({"buildings": ["office 6"]}, "building id 'office 6' may only use"),
    ({"buildings": ["a/b"]}, "may only use"),
    ({"buildings": ["a+"]}, "may only use"),
    ({"buildings": []}, "at least one building"),
    ({"buildings": ["a", "a"]}, "duplicates"),
    ({"buildings": ["zonecast"]}, "service user's name"),
    ({"buildings": ["a"], "service_user": "svc#"}, "service user 'svc#'"),
    ({"buildings": ["a"], "prefix": "zc/#"}, "topic prefix"),
    ({"buildings": ["a"], "rotate": ["b"]}, "cannot rotate"),
])
def test_bad_input_says_what_to_fix(tmp_path, kwargs, match):
    with pytest.raises(ValueError, match=match):
        write_broker_files(out=tmp_path / "auth", **kwargs)
    assert not (tmp_path / "auth" / "passwd").exists()


def test_cli_writes_the_files(tmp_path):
    out = tmp_path / "auth"
    r = CliRunner().invoke(cli, ["mqtt-config", "--buildings", "office6, office7", "--out",
                                 str(out), "--prefix", "site1"])
    assert r.exit_code == 0, r.output
    assert "credentials.txt" in r.output
    assert list(read_passwd(out / "passwd")) == ["zonecast", "office6", "office7"]
    assert "pattern write site1/%u/telemetry" in (out / "acl").read_text()
    r = CliRunner().invoke(cli, ["mqtt-config", "--buildings", "zonecast", "--out", str(out)])
    assert r.exit_code == 2 and "service user's name" in r.output
