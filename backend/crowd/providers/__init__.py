"""The crowd providers, chosen by name (``get_provider``).

Only the MTurk provider's completion is here: publishing, review and pay still go through
``backend.crowd.client``.
"""

from __future__ import annotations

from typing import Any, cast

from backend.crowd.provider import PROVIDERS, Completion, CrowdProvider, ProviderRefused


class _MTurkCompletion:
    """MTurk's way back from the page (any compatible endpoint, our marketplace included)."""

    name = "mturk"

    def completion(self, unit_id: str, assignment_id: str) -> Completion:
        """MTurk's externalSubmit form. MTurk names the host to post to per assignment
        (``turkSubmitTo`` in the page's address: the sandbox, production or our marketplace),
        so the url stays empty and the page posts to ``{turkSubmitTo}/mturk/externalSubmit``."""
        return Completion("form_post", "")


def get_provider(name: str | None = None) -> CrowdProvider:
    """The provider named ``name`` ("mturk" when None)."""
    name = name or "mturk"
    if name != "mturk":
        raise ProviderRefused(f"unknown crowd provider {name!r}: choose one of "
                              f"{', '.join(PROVIDERS)}", "get_provider",
                              [{"field": "provider", "message": f"unknown: {name!r}"}])
    return cast(Any, _MTurkCompletion())
