"""Progress tests: the app and its marketplace served by uvicorn (the crowd tests' fixtures,
used here by name), simulated workers submitting over HTTP."""

from __future__ import annotations

from tests.backend.crowd.conftest import api, crowd_url, market_env, mturk
from tests.backend.market.conftest import market_database_url, market_url, migrated_sqlite

__all__ = ["api", "crowd_url", "market_database_url", "market_env", "market_url",
           "migrated_sqlite", "mturk"]
