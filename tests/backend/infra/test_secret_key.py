"""The signing key: no default anyone could know. Unset in dev, each instance makes its own
random key once and keeps it in {VAR_DIR}/secret_key (mode 0600); prod refuses to start
without a long one; a refused key never shows in an error or a log; the image runs prod."""

from __future__ import annotations

import re
import secrets
import stat
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest
import yaml
from fastapi.testclient import TestClient
from pydantic import ValidationError

from backend.config import PLACEHOLDER_SECRETS, TEST_SECRET, InvalidSettings, Settings
from backend.security import sign_token
from tests.backend.cli.conftest import clean_env
from tests.conftest import reset_caches

ROOT = Path(__file__).resolve().parents[3]
PUBLIC_DEFAULT = "dev-secret-change-me"  # the signing key every dev instance once shared


@pytest.fixture
def database_url(tmp_path: Path) -> str:
    """SQLite only: a dev instance makes its own key only as the single-folder embedded
    default (on PostgreSQL or Redis it must be given one)."""
    return f"sqlite:///{tmp_path / 'test.db'}"


def _dev(monkeypatch: pytest.MonkeyPatch, var_dir: Path) -> Settings:
    monkeypatch.setenv("DEXLABEL_ENV", "dev")
    monkeypatch.setenv("DEXLABEL_VAR_DIR", str(var_dir))
    monkeypatch.delenv("DEXLABEL_SECRET_KEY", raising=False)
    return Settings()


def test_a_dev_instance_makes_its_own_key_once_and_keeps_it_private(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    first = _dev(monkeypatch, tmp_path / "one")
    assert not (tmp_path / "one").exists(), "loading the settings makes nothing"
    key = first.signing_key
    stored = tmp_path / "one" / "secret_key"
    assert stat.S_IMODE(stored.stat().st_mode) == 0o600
    assert stored.read_text().strip() == key and len(key) >= 32
    assert key not in {PUBLIC_DEFAULT, TEST_SECRET, ""}
    assert _dev(monkeypatch, tmp_path / "one").signing_key == key  # every process alike
    assert _dev(monkeypatch, tmp_path / "two").signing_key != key  # every instance its own
    assert key not in repr(first) and key not in str(first.model_dump_json())


def test_a_dev_instance_refuses_tokens_signed_with_the_former_public_default(
    app_env: dict, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    from backend.accounts.service import create_admin
    from backend.app import create_app
    from backend.db import session_scope

    monkeypatch.setenv("DEXLABEL_ENV", "dev")
    reset_caches()
    with session_scope() as session:
        admin = create_admin(session, "dev-admin@example.org", "a long password")
        admin_id, epoch = admin.id, admin.token_epoch
    with TestClient(create_app()) as client:
        for key in (PUBLIC_DEFAULT, TEST_SECRET):
            forged = sign_token({"scope": "admin", "sub": admin_id, "epoch": epoch}, key, 3600)
            resp = client.get("/api/auth/me", headers={"Authorization": f"Bearer {forged}"})
            assert resp.status_code == 401, f"a token signed with {key!r} was accepted"
        login = client.post("/api/auth/token", json={"email": "dev-admin@example.org",
                                                     "password": "a long password"})
        token = login.json()["access_token"]
        assert client.get("/api/auth/me",
                          headers={"Authorization": f"Bearer {token}"}).status_code == 200


def test_a_well_known_placeholder_is_refused_in_every_mode(
    monkeypatch: pytest.MonkeyPatch
) -> None:
    for env in ("dev", "test", "prod"):
        monkeypatch.setenv("DEXLABEL_ENV", env)
        for placeholder in PLACEHOLDER_SECRETS:
            monkeypatch.setenv("DEXLABEL_SECRET_KEY", placeholder)
            with pytest.raises(ValidationError, match="placeholder"):
                Settings()


def test_prod_refuses_to_start_without_a_key(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DEXLABEL_ENV", "prod")
    monkeypatch.delenv("DEXLABEL_SECRET_KEY", raising=False)
    monkeypatch.setenv("DEXLABEL_MARKET_REQUESTERS", "AKIAPRODREQUESTER000:" + "s3" * 20)
    with pytest.raises(ValidationError, match="DEXLABEL_SECRET_KEY is not set"):
        Settings()


SHORT_SECRET = "Zq7-prod-secret-tail-9XKW"  # too short for prod: refused at start


def _tails(secret: str) -> list[str]:
    return [secret, secret[-20:], secret[-12:], secret[:12]]


def test_a_refused_key_never_shows_in_the_error(monkeypatch: pytest.MonkeyPatch) -> None:
    from backend.config import get_settings

    monkeypatch.setenv("DEXLABEL_ENV", "prod")
    monkeypatch.setenv("DEXLABEL_SECRET_KEY", SHORT_SECRET)
    with pytest.raises(ValidationError) as refused:
        Settings()
    shown = str(refused.value) + repr(refused.value)
    assert "DEXLABEL_SECRET_KEY is too short" in shown
    for part in _tails(SHORT_SECRET):
        assert part not in shown
    get_settings.cache_clear()
    try:
        with pytest.raises(InvalidSettings) as described:
            get_settings()
    finally:
        get_settings.cache_clear()
    assert "DEXLABEL_SECRET_KEY" in described.value.detail
    assert not any(part in described.value.detail for part in _tails(SHORT_SECRET))


def test_a_server_refused_for_its_key_does_not_log_the_key(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "backend.cli", "serve", "--port", "1"], cwd=tmp_path,
        env=clean_env(DEXLABEL_ENV="prod", DEXLABEL_SECRET_KEY=SHORT_SECRET,
                      DEXLABEL_VAR_DIR=str(tmp_path / "var")),
        capture_output=True, text=True, timeout=120)
    output = done.stdout + done.stderr
    assert done.returncode != 0 and "DEXLABEL_SECRET_KEY" in output, output
    assert not any(part in output for part in _tails(SHORT_SECRET)), output


def test_the_image_runs_prod_so_it_needs_real_keys() -> None:
    """The Dockerfile's default command serves in prod mode: without DEXLABEL_SECRET_KEY (and
    real marketplace keys) the container refuses to start instead of serving dev defaults."""
    dockerfile = (ROOT / "Dockerfile").read_text()
    env = dict(re.findall(r"^ENV\s+(DEXLABEL_\w+)=(\S+)", dockerfile, re.MULTILINE))
    assert env.get("DEXLABEL_ENV") == "prod"
    cmd = re.search(r"^CMD\s+(\[.*\])", dockerfile, re.MULTILINE)
    assert cmd is not None and '"serve"' in cmd.group(1)
    monkeypatch = pytest.MonkeyPatch()
    try:
        monkeypatch.setenv("DEXLABEL_ENV", env["DEXLABEL_ENV"])
        monkeypatch.delenv("DEXLABEL_SECRET_KEY", raising=False)
        with pytest.raises(ValidationError, match="DEXLABEL_SECRET_KEY"):
            Settings()
    finally:
        monkeypatch.undo()
    # docker compose sets prod and asks for both keys before it starts anything.
    compose = yaml.safe_load((ROOT / "docker-compose.yml").read_text())
    for name in ("migrate", "api", "worker"):
        service_env = compose["services"][name]["environment"]
        assert service_env["DEXLABEL_ENV"] == "prod"
        assert ":?" in service_env["DEXLABEL_SECRET_KEY"]
        assert ":?" in service_env["DEXLABEL_MARKET_REQUESTERS"]


SHARED = {"DEXLABEL_DATABASE_URL": "postgresql+psycopg://dexlabel@127.0.0.1:1/dexlabel",
          "DEXLABEL_REDIS_URL": "redis://127.0.0.1:1/0"}


@pytest.mark.parametrize("setting", sorted(SHARED))
def test_a_dev_deployment_on_a_server_refuses_to_start_without_a_key(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, setting: str
) -> None:
    """Hosts sharing PostgreSQL or Redis share no folder: a key each made for itself would
    make every host refuse the others' tokens. Checked before anything is reached."""
    monkeypatch.setenv(setting, SHARED[setting])
    with pytest.raises(ValidationError, match="DEXLABEL_SECRET_KEY is not set; a deployment "
                                              "on PostgreSQL or Redis"):
        _dev(monkeypatch, tmp_path / "var")
    assert not (tmp_path / "var").exists(), "no per-folder key was made"
    monkeypatch.setenv("DEXLABEL_SECRET_KEY", secrets.token_hex(32))
    assert Settings().shared_deployment


def test_serve_with_several_workers_refuses_to_start_without_a_key(tmp_path: Path) -> None:
    """``serve --workers 2`` needs PostgreSQL, so it needs the key too: one line naming it."""
    done = subprocess.run(
        [sys.executable, "-m", "backend.cli", "serve", "--workers", "2", "--port", "1"],
        cwd=tmp_path, env=clean_env(DEXLABEL_ENV="dev", DEXLABEL_VAR_DIR=str(tmp_path / "var"),
                                    DEXLABEL_DATABASE_URL=SHARED["DEXLABEL_DATABASE_URL"]),
        capture_output=True, text=True, timeout=120)
    output = (done.stdout + done.stderr).strip()
    assert done.returncode != 0, output
    assert "DEXLABEL_SECRET_KEY is not set" in output and "Traceback" not in output, output
    assert len([line for line in output.splitlines() if "SECRET_KEY" in line]) == 1, output
    assert not (tmp_path / "var" / "secret_key").exists()


@pytest.mark.parametrize("secret", ["a" * 40, "password" * 5, "ab" * 20,
                                    "abcd1234" * 5, "aaaaaaaaab" * 3 + "cdefghijklmn"])
def test_prod_refuses_a_long_key_that_is_not_random(
    monkeypatch: pytest.MonkeyPatch, secret: str
) -> None:
    monkeypatch.setenv("DEXLABEL_ENV", "prod")
    monkeypatch.setenv("DEXLABEL_SECRET_KEY", secret)
    monkeypatch.setenv("DEXLABEL_MARKET_REQUESTERS", "AKIAPRODREQUESTER000:" + "s3" * 20)
    with pytest.raises(ValidationError, match="DEXLABEL_SECRET_KEY does not look random") as err:
        Settings()
    assert secret not in str(err.value)


@pytest.mark.parametrize("make", [lambda: secrets.token_hex(16), lambda: secrets.token_hex(32),
                                  lambda: secrets.token_urlsafe(32)])
def test_prod_accepts_random_keys_as_the_usual_tools_make_them(
    monkeypatch: pytest.MonkeyPatch, make: Callable[[], str]
) -> None:
    monkeypatch.setenv("DEXLABEL_ENV", "prod")
    monkeypatch.setenv("DEXLABEL_MARKET_REQUESTERS", "AKIAPRODREQUESTER000:" + "s3" * 20)
    for _ in range(50):
        key = make()
        monkeypatch.setenv("DEXLABEL_SECRET_KEY", key)
        assert Settings().signing_key == key
