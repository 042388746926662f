"""Participant groups and messages: Prolific's allow-lists, blocks and notes to participants.

A block is membership of the workspace's "dexlabel blocked" group, which every study we
publish excludes (the ``participant_group_blocklist`` filter); an allow-list (the training
group, or any ``Requirements.group``) is a group a study admits alone
(``participant_group_allowlist``). Prolific's groups hold members, not values: a grant's value
is not kept anywhere on Prolific.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from backend.config import Settings
from backend.crowd.provider import ProviderError, Requirements
from backend.crowd.providers.prolific.client import ProlificClient

BLOCKED_GROUP = "dexlabel blocked"
TRAINING_GROUP = "dexlabel training"
GROUPS = "/api/v1/participant-groups/"


def find_group(client: ProlificClient, settings: Settings, name: str) -> str | None:
    """The id of the workspace's participant group called ``name``, or None."""
    params = {"workspace_id": settings.prolific_workspace_id} \
        if settings.prolific_workspace_id else {}
    for group in _results(client.get(GROUPS, **params)):
        if group.get("name") == name:
            return str(group["id"])
    return None


def ensure_group(client: ProlificClient, settings: Settings, name: str) -> str:
    """The id of the group called ``name``, made first where there is none."""
    found = find_group(client, settings, name)
    if found is not None:
        return found
    body: dict[str, Any] = {"name": name}
    if settings.prolific_workspace_id:
        body["workspace_id"] = settings.prolific_workspace_id
    return str(client.post(GROUPS, body)["id"])


def add_member(client: ProlificClient, group_id: str, participant_id: str) -> None:
    client.post(f"{GROUPS}{group_id}/participants/", {"participant_ids": [participant_id]})


def remove_member(client: ProlificClient, group_id: str, participant_id: str) -> None:
    try:
        client.request("DELETE", f"{GROUPS}{group_id}/participants/",
                       json={"participant_ids": [participant_id]})
    except ProviderError as exc:
        if exc.reason != "not_found":  # not a member: nothing to take away
            raise


def study_filters(client: ProlificClient, settings: Settings,
                  requirements: Requirements) -> list[dict[str, Any]]:
    """Prolific filters for who may take a study: never the blocked group; only ``group``
    where one is named; at least ``min_approval_rate`` percent approved. Locales have no
    filter of ours on Prolific (its country filters use its own ids) and are not sent."""
    filters: list[dict[str, Any]] = []
    blocked = find_group(client, settings, BLOCKED_GROUP)
    if blocked is not None:
        filters.append({"filter_id": "participant_group_blocklist",
                        "selected_values": [blocked]})
    if requirements.group:
        filters.append({"filter_id": "participant_group_allowlist",
                        "selected_values": [requirements.group]})
    if requirements.min_approval_rate is not None:
        filters.append({"filter_id": "approval_rate",
                        "selected_range": {"lower": requirements.min_approval_rate,
                                           "upper": 100}})
    return filters


def send_messages(client: ProlificClient, participant_ids: Sequence[str], subject: str,
                  message: str) -> list[dict[str, str]]:
    """One message per participant; the ones that did not go out, with why."""
    failures = []
    for participant in participant_ids:
        try:
            client.post("/api/v1/messages/", {"recipient_id": participant,
                                              "body": f"{subject}\n\n{message}"})
        except ProviderError as exc:
            failures.append({"worker_id": participant, "reason": exc.reason,
                             "detail": exc.detail})
    return failures


def _results(page: Any) -> list[dict[str, Any]]:
    if isinstance(page, dict):
        return list(page.get("results", []))
    return list(page or [])
