"""Reviewing on Prolific: a rejection's message and category are checked before any call;
approving twice is not an error; submissions come back in our statuses, each with its unit;
blocks, allow-lists and messages go through participant groups and messages."""

from __future__ import annotations

from typing import Any

import pytest

from backend.crowd.provider import CrowdProvider, ProviderError, ProviderRefused
from backend.crowd.providers.prolific.submissions import our_status
from tests.backend.crowd.test_prolific_publish import units

WHY = ("The hand points were placed on the wrong hand in most frames, and the thumb tip was "
       "left on the first frame's position for the whole clip.")


def test_the_provider_is_a_crowd_provider(prolific_provider: Any) -> None:
    assert isinstance(prolific_provider, CrowdProvider)
    fees = prolific_provider.fees()
    assert (fees.provider, fees.currency, fees.reward_fee_cents(300)) == ("prolific", "GBP", 100)


@pytest.mark.parametrize(("message", "category", "field"), [
    (WHY[:99], "LOW_EFFORT", "feedback"),
    ("   " + WHY[:99] + "   ", "LOW_EFFORT", "feedback"),
    (WHY, None, "category"),
    (WHY, "SLOPPY", "category"),
])
def test_a_rejection_prolific_would_refuse_is_refused_before_any_call(
        prolific: Any, prolific_provider: Any, message: str, category: str | None,
        field: str) -> None:
    with pytest.raises(ProviderRefused) as caught:
        prolific_provider.reject("sub-any", message, category)
    assert caught.value.extra["fields"][0]["field"] == field
    assert prolific.requests == []


def test_review_and_submissions_in_our_words(prolific: Any, prolific_provider: Any) -> None:
    first, second = prolific_provider.publish(units(2))
    study_id = first.unit_id.split(":")[0]
    taken = {name: prolific.take(study_id, position, f"PID-{name}", status)
             for name, position, status in [("a", 0, "AWAITING REVIEW"), ("b", 1, "ACTIVE"),
                                            ("c", 1, "AWAITING REVIEW"),
                                            ("d", 0, "TIMED-OUT")]}

    collected = {r.worker_id: (r.unit_id, r.status)
                 for r in prolific_provider.submissions([first.unit_id, second.unit_id])}
    assert collected == {"PID-a": (first.unit_id, "submitted"),
                         "PID-c": (second.unit_id, "submitted")}
    state = prolific_provider.unit(second.unit_id)
    assert (state.places, state.held, state.submitted, state.open) == (2, 1, 1, False)

    prolific_provider.approve(taken["a"], None)
    prolific_provider.approve(taken["a"], None)  # already approved: fine
    prolific_provider.reject(taken["c"], WHY, "LOW_EFFORT")
    assert prolific_provider.submission(taken["a"]).status == "approved"
    assert prolific_provider.submission(taken["c"]).status == "rejected"
    with pytest.raises(ProviderError) as caught:
        prolific_provider.approve(taken["c"], None)  # rejected: no approving it now
    assert caught.value.reason == "invalid_state"
    assert prolific_provider.submission("sub-none") is None


def test_every_prolific_status_maps_to_ours() -> None:
    assert [our_status(s) for s in ("RESERVED", "ACTIVE", "AWAITING REVIEW", "APPROVED",
                                     "REJECTED", "RETURNED", "TIMED-OUT", "SCREENED OUT",
                                     "awaiting_review")] == [
        "held", "held", "submitted", "approved", "rejected", "returned", "returned",
        "returned", "submitted"]
    with pytest.raises(ProviderError, match="unknown submission status"):
        our_status("PARTIALLY APPROVED")


def test_blocks_groups_and_messages(prolific: Any, prolific_provider: Any) -> None:
    prolific_provider.block("PID-x", "spam")
    group = prolific_provider.training_group()
    assert prolific_provider.training_group() == group
    prolific_provider.grant("PID-y", group, 1, True)
    members = {g["name"]: g["members"] for g in prolific.groups.values()}
    assert members == {"dexlabel blocked": {"PID-x"}, "dexlabel training": {"PID-y"}}
    assert [m["recipient_id"] for m in prolific.messages] == ["PID-y"]

    prolific_provider.publish(units(1))
    (study,) = prolific.studies.values()
    assert study["filters"][0]["filter_id"] == "participant_group_blocklist"
    prolific_provider.unblock("PID-x", None)
    prolific_provider.revoke("PID-y", group, None)
    assert all(not g["members"] for g in prolific.groups.values())
    assert prolific_provider.notify(["PID-1", "PID-2"], "Hello", "New work is up") == []


def test_submissions_are_read_page_by_page(prolific: Any, prolific_provider: Any) -> None:
    (unit,) = prolific_provider.publish(units(1))
    study_id = unit.unit_id.split(":")[0]
    for n in range(450):  # three pages of 200
        prolific.take(study_id, 0, f"PID{n:03d}")
    found = list(prolific_provider.submissions([unit.unit_id]))
    assert sorted(r.worker_id for r in found) == [f"PID{n:03d}" for n in range(450)]
    pages = [path for _, path in prolific.requests if path.endswith("/submissions/")]
    assert len(pages) == 3
