"""The crowd providers, chosen by name: ``get_provider("mturk")``.

Each provider is a module (or package) ``backend.crowd.providers.<name>`` with a
``make(settings) -> CrowdProvider``, imported only when first asked for, so a deployment that
never publishes to Prolific never imports its client. These modules are the only ones that
import a crowd's SDK (boto3 for MTurk) or name its operations; lint enforces it
(tests/lint.sh, pyproject's banned-api and tests/crowd_operations.py).

Rows that point at a crowd (HITs, assignments, payments, blocks) carry the ``provider`` that
holds them: their ids (``hit_id``, ``external_id``, ``worker_id``) are that provider's opaque
strings, and ``get_provider(row.provider)`` is the one to ask about them.
"""

from __future__ import annotations

import importlib
from typing import Any

from backend.config import Settings, get_settings
from backend.crowd.provider import PROVIDERS, CrowdProvider, FeeSchedule
from backend.errors import DexlabelError


class UnknownProvider(DexlabelError, status_code=422, code="unknown_provider"):
    """A provider name that is not one of ``PROVIDERS``."""


def get_provider(name: str | None = None, settings: Settings | None = None) -> CrowdProvider:
    """The provider ``name`` (None: the setting DEXLABEL_CROWD_PROVIDER) for ``settings``
    (None: this process's settings)."""
    settings = settings or get_settings()
    name = name or settings.crowd_provider
    if name not in PROVIDERS:
        raise UnknownProvider(f"no crowd provider {name!r}: choose one of "
                              f"{', '.join(PROVIDERS)}", field="provider")
    path = f"{__name__}.{name}"
    try:
        module = importlib.import_module(path)
    except ModuleNotFoundError as exc:
        if exc.name != path:
            raise
        raise UnknownProvider(f"the crowd provider {name!r} is not part of this installation",
                              field="provider") from exc
    provider: CrowdProvider = module.make(settings)
    return provider


def provider_of(crowd: CrowdProvider | Any) -> CrowdProvider:
    """``crowd`` as a provider: a provider as it is; anything else is taken as a requester
    client of an MTurk-compatible endpoint (boto3's ``mturk`` client, as the scripts and
    tests that make one themselves pass it) and wrapped in the mturk provider."""
    if isinstance(crowd, CrowdProvider):
        return crowd
    from backend.crowd.providers.mturk import MTurkProvider

    return MTurkProvider(get_settings(), client=crowd)


def fees_of(name: str) -> FeeSchedule:
    """The fee schedule of the provider ``name`` (no call to the provider)."""
    return get_provider(name).fees()
