"""Publishing to Prolific: a batch of units is one Taskflow study, whatever its size, made
once even when a reply is lost; the pay floor is checked before any call; the study's places
only go up, and close/extend say what Prolific allows."""

from __future__ import annotations

from typing import Any

import pytest

from backend.crowd.provider import ProviderRefused, ProviderUnreachable, UnitSpec


def units(count: int, reward_cents: int = 50, expected_s: int = 120,
          prefix: str = "k") -> list[UnitSpec]:
    return [UnitSpec(key=f"{prefix}{i}", task_id=i + 1, title="Label a hand",
                     description="Click 21 hand points in each frame", keywords="hand",
                     page_url=f"http://127.0.0.1:8000/annotate/?task=tok{i}",
                     reward_cents=reward_cents, places=1 + i % 2, lifetime_s=86400,
                     allotted_s=1800, auto_approve_s=259200, expected_s=expected_s,
                     frame_height=600, note=f"dexlabel task {i + 1} round 1")
            for i in range(count)]


def test_two_thousand_units_are_one_taskflow_study(prolific: Any,
                                                   prolific_provider: Any) -> None:
    batch = units(2000)
    published = prolific_provider.publish(batch)

    assert prolific.counts["studies_created"] == 1
    (study,) = prolific.studies.values()
    assert len(study["access_details"]) == 2000
    assert study["total_available_places"] == sum(unit.places for unit in batch) == 3000
    assert study["status"] == "ACTIVE"
    assert [a["total_allocation"] for a in study["access_details"][:3]] == [1, 2, 1]
    assert study["access_details"][7]["external_url"] == (
        "http://127.0.0.1:8000/annotate/?task=tok7&PROLIFIC_PID={%PROLIFIC_PID%}"
        "&STUDY_ID={%STUDY_ID%}&SESSION_ID={%SESSION_ID%}")
    assert [p.unit_id for p in published[:2]] == [f"{study['id']}:0", f"{study['id']}:1"]
    assert {p.outcome for p in published} == {"created"}
    # Our completion code replaced the one Prolific made at creation.
    (code,) = study["completion_codes"]
    assert code["code"] != "C" + study["id"][-6:].upper()
    completion = prolific_provider.completion(published[0].unit_id, "sub1")
    assert (completion.kind, completion.url) == (
        "redirect", f"https://app.prolific.com/submissions/complete?cc={code['code']}")

    again = prolific_provider.publish(batch)
    assert prolific.counts["studies_created"] == 1
    assert [p.unit_id for p in again] == [p.unit_id for p in published]
    assert {p.outcome for p in again} == {"recovered"}


def test_a_lost_creation_reply_finds_the_draft_instead_of_making_another(
        prolific: Any, prolific_provider: Any) -> None:
    prolific.faults["drop_after_create"] = 1
    with pytest.raises(ProviderUnreachable):
        prolific_provider.publish(units(3))
    assert prolific.counts["studies_created"] == 1

    published = prolific_provider.publish(units(3))
    assert prolific.counts["studies_created"] == 1
    (study,) = prolific.studies.values()
    assert study["status"] == "ACTIVE"
    assert published[0].unit_id == f"{study['id']}:0"


def test_a_reward_under_the_pay_floor_is_refused_before_any_call(
        prolific: Any, prolific_provider: Any) -> None:
    with pytest.raises(ProviderRefused) as caught:
        prolific_provider.check_publish(units(2, reward_cents=5, expected_s=120))
    assert caught.value.extra["fields"][0]["field"] == "reward"
    assert "GBP 1.50 an hour" in caught.value.detail
    assert "minimum hourly rate of GBP 6.00" in caught.value.detail
    with pytest.raises(ProviderRefused):
        prolific_provider.publish(units(2, reward_cents=5, expected_s=120))
    assert prolific.requests == []
    # GBP 0.20 for 120 s is exactly GBP 6.00 an hour: taken.
    prolific_provider.check_publish(units(1, reward_cents=20, expected_s=120))


def test_places_only_go_up_and_each_request_counts_once(prolific: Any,
                                                         prolific_provider: Any) -> None:
    published = prolific_provider.publish(units(2))
    (study,) = prolific.studies.values()
    assert study["total_available_places"] == 3
    prolific_provider.add_places(published[1].unit_id, 2, "more-1")
    prolific_provider.add_places(published[1].unit_id, 2, "more-1")
    assert study["total_available_places"] == 5
    state = prolific_provider.unit(published[1].unit_id)
    assert (state.places, state.open) == (4, True)


def test_close_stops_the_study_once_every_unit_is_closed_and_extend_is_refused(
        prolific: Any, prolific_provider: Any) -> None:
    first, second = prolific_provider.publish(units(2))
    (study,) = prolific.studies.values()
    prolific_provider.close(first.unit_id)
    assert prolific_provider.unit(first.unit_id).open is False
    assert prolific_provider.unit(second.unit_id).open is True
    assert study["status"] == "ACTIVE"
    prolific_provider.close(second.unit_id)
    assert study["status"] == "COMPLETED"
    with pytest.raises(ProviderRefused, match="no expiry"):
        prolific_provider.extend(first.unit_id, 3600)
