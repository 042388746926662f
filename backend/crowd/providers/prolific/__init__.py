"""Prolific (docs.prolific.com) as a crowd: ``make(settings)`` gives its CrowdProvider.

Our own small client (there is no official Python SDK), Taskflow studies for publishing, the
bonus ledger, participant groups, and the webhook route (``webhooks.router``, mounted by the
app) that records submissions as ``crowd sync`` does. A missed webhook is caught by the
periodic sync, which reads the provider's ``submissions()``.
"""

from __future__ import annotations

from backend.config import Settings
from backend.crowd.provider import CrowdProvider


def make(settings: Settings) -> CrowdProvider:
    """The Prolific provider of the workspace the settings name (token, API address)."""
    from backend.crowd.providers.prolific.provider import ProlificProvider

    return ProlificProvider(settings)
