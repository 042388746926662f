"""The MTurk requester client's names at their former address.

The client now lives with the mturk provider (``backend.crowd.providers.mturk_client``); the
crowd domain reaches any crowd only through ``backend.crowd.providers``. These names stay for
the scripts and tests that make a requester client of the configured endpoint themselves.
"""

from __future__ import annotations

from backend.crowd.providers.mturk_client import (
    AWS_PRODUCTION_ENDPOINT,
    AWS_SANDBOX_ENDPOINT,
    CrowdConfigError,
    MarketplaceError,
    MarketplaceRefused,
    MarketplaceUnreachable,
    MTurkClient,
    builtin_endpoint,
    call,
    call_naming,
    credentials,
    endpoint_hint,
    endpoint_url,
    make_client,
    paginate,
)

__all__ = [
    "AWS_PRODUCTION_ENDPOINT", "AWS_SANDBOX_ENDPOINT", "CrowdConfigError", "MTurkClient",
    "MarketplaceError", "MarketplaceRefused", "MarketplaceUnreachable", "builtin_endpoint",
    "call", "call_naming", "credentials", "endpoint_hint", "endpoint_url", "make_client",
    "paginate",
]
