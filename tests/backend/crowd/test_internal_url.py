"""DEXLABEL_INTERNAL_URL: a process whose browsers' address (PUBLIC_URL) is not the app from
where it runs (a queue worker in a container) reaches the built-in marketplace at the internal
address, while the links it hands to browsers keep the public one."""

from __future__ import annotations

from typing import Any

import pytest

from backend.config import Settings
from tests.conftest import reset_caches

# An address nothing answers at (port 9 is discard; nothing listens there on the test hosts).
UNREACHABLE = "http://127.0.0.1:9"


def _client_at(monkeypatch: pytest.MonkeyPatch, public: str, internal: str | None) -> Any:
    from backend.config import get_settings
    from backend.crowd.client import make_client

    monkeypatch.setenv("DEXLABEL_PUBLIC_URL", public)
    if internal is None:
        monkeypatch.delenv("DEXLABEL_INTERNAL_URL", raising=False)
    else:
        monkeypatch.setenv("DEXLABEL_INTERNAL_URL", internal)
    reset_caches()
    return make_client(get_settings(), attempts=1)


def test_workers_reach_the_marketplace_at_the_internal_url_and_link_the_public_one(
    market_env: dict[str, str], market_url: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    from backend.crowd import flows
    from backend.crowd.schemas import PublishOptions
    from backend.db import session_scope
    from tests.backend.crowd.helpers import make_tasks

    public = "https://labels.example.org"
    client = _client_at(monkeypatch, public, market_url)
    assert client.meta.endpoint_url == f"{market_url}/mturk"
    make_tasks(1)
    with session_scope() as session:
        result = flows.publish(session, client, PublishOptions(min_approval_rate=None), None)
    assert len(result.hit_ids) == 1
    hit = client.get_hit(HITId=result.hit_ids[0])["HIT"]
    # The HIT's page is for browsers: the public address, never the internal one.
    assert f"<ExternalURL>{public}/annotate/?task=" in hit["Question"]
    assert market_url not in hit["Question"]


def test_without_the_internal_url_an_unreachable_public_url_names_its_setting(
    market_env: dict[str, str], monkeypatch: pytest.MonkeyPatch
) -> None:
    from backend.crowd.client import MarketplaceUnreachable, call

    client = _client_at(monkeypatch, UNREACHABLE, None)
    with pytest.raises(MarketplaceUnreachable, match="check DEXLABEL_PUBLIC_URL"):
        call(client, "get_account_balance")
    client = _client_at(monkeypatch, "https://labels.example.org", UNREACHABLE)
    with pytest.raises(MarketplaceUnreachable, match="check DEXLABEL_INTERNAL_URL"):
        call(client, "get_account_balance")


@pytest.mark.parametrize("value", ["api:8000", "ftp://api", "http://"])
def test_an_internal_url_that_is_not_an_http_address_is_refused(value: str) -> None:
    with pytest.raises(ValueError, match="internal_url"):
        Settings(internal_url=value)


def test_the_internal_url_loses_its_trailing_slash() -> None:
    assert Settings(internal_url="http://api:8000/").internal_url == "http://api:8000"
