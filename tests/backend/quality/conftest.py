"""QC tests run the product end to end: the app and its marketplace served by uvicorn, simulated
workers over HTTP, the QC job, boto3 reading the marketplace's record.
The synthetic captures they use are in tests/backend/conftest.py."""

from __future__ import annotations

from tests.backend.crowd.conftest import crowd_url, market_env
from tests.backend.market.conftest import market_database_url, market_url, migrated_sqlite

__all__ = ["crowd_url", "market_database_url", "market_env", "market_url", "migrated_sqlite"]
