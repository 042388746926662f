from __future__ import annotations

import time

import pytest
from pydantic import ValidationError

from backend.config import Settings
from backend.errors import Unauthorized
from backend.security import hash_password, sign_token, verify_password, verify_token

PROD_KEY = "kq3V9xT2mZ7rB4wN8pL1cH6yD5fJ0sGa"  # 32 characters, 32 distinct


def test_defaults_are_the_embedded_deployment(monkeypatch: pytest.MonkeyPatch, tmp_path) -> None:
    for name in ("DEXLABEL_DATABASE_URL", "DEXLABEL_STORAGE_URL", "DEXLABEL_REDIS_URL"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("DEXLABEL_VAR_DIR", str(tmp_path))
    s = Settings()
    assert s.database_url == f"sqlite:///{tmp_path.as_posix()}/dexlabel.db"
    assert s.storage_url == f"{tmp_path.as_posix()}/storage"
    assert s.redis_url is None and s.queue_path == tmp_path / "queue.db"


@pytest.mark.parametrize("secret",
                         ["dev-secret-change-me", "changeme", "short-but-not-placeholder"])
def test_prod_refuses_a_placeholder_or_short_secret(
    monkeypatch: pytest.MonkeyPatch, secret: str
) -> None:
    monkeypatch.setenv("DEXLABEL_ENV", "prod")
    monkeypatch.setenv("DEXLABEL_SECRET_KEY", secret)
    with pytest.raises(ValidationError, match="SECRET_KEY"):
        Settings()


def test_prod_accepts_a_long_random_secret(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DEXLABEL_ENV", "prod")
    monkeypatch.setenv("DEXLABEL_SECRET_KEY", PROD_KEY)
    monkeypatch.setenv("DEXLABEL_MARKET_REQUESTERS", "AKIAPRODREQUESTER000:" + "s3" * 20)
    assert Settings().env == "prod"


def test_prod_refuses_the_dev_market_key_pair(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DEXLABEL_ENV", "prod")
    monkeypatch.setenv("DEXLABEL_SECRET_KEY", PROD_KEY)
    monkeypatch.delenv("DEXLABEL_MARKET_REQUESTERS", raising=False)
    with pytest.raises(ValidationError, match="dev key pair"):
        Settings()


def test_market_requesters_parse_with_optional_balances(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DEXLABEL_MARKET_REQUESTERS", "AKIAFIRSTREQUESTER00:one, "
                                                     "AKIASECONDREQUESTER0:two:12.5")
    accounts = Settings().market_requester_accounts
    assert {key: (r.secret_key, r.start_balance_cents) for key, r in accounts.items()} == {
        "AKIAFIRSTREQUESTER00": ("one", 1_000_000), "AKIASECONDREQUESTER0": ("two", 1250)}
    for bad in ("AKIAFIRSTREQUESTER00", "short:secret", "AKIAFIRSTREQUESTER00:s:lots"):
        monkeypatch.setenv("DEXLABEL_MARKET_REQUESTERS", bad)
        with pytest.raises(ValidationError):
            Settings()


def test_password_hash_verifies_only_the_right_password() -> None:
    stored = hash_password("a long password")
    assert verify_password("a long password", stored)
    assert not verify_password("a long passwore", stored)
    assert stored != hash_password("a long password")  # salted


def test_token_round_trip_and_tampering() -> None:
    token = sign_token({"scope": "view", "sequence_id": 3}, "k" * 32, 60)
    assert verify_token(token, "k" * 32, "view")["sequence_id"] == 3
    with pytest.raises(Unauthorized, match="signature"):
        verify_token(token, "other" * 8, "view")
    with pytest.raises(Unauthorized, match="not valid for admin"):
        verify_token(token, "k" * 32, "admin")
    raw, sig = token.split(".")
    with pytest.raises(Unauthorized):
        verify_token(raw[:-2] + "AA." + sig, "k" * 32, "view")


def test_expired_token_is_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    token = sign_token({"scope": "admin", "sub": 1}, "k" * 32, 10)
    monkeypatch.setattr(time, "time", lambda: 10**12)
    with pytest.raises(Unauthorized, match="expired"):
        verify_token(token, "k" * 32, "admin")
