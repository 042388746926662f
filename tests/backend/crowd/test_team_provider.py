"""The team provider: units on the built-in marketplace's team account, taken by portal
accounts through the portal's HTTP API, served by uvicorn on loopback; nothing is ever paid."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import httpx
import pytest

from backend.config import get_settings, team_market_requester
from backend.crowd import client as requester
from backend.crowd.provider import (
    BonusOrder,
    CrowdProvider,
    ProviderError,
    ProviderRefused,
    Requirements,
    UnitSpec,
)
from backend.crowd.providers.team import external_question, make
from tests.backend.crowd.helpers import admin_headers
from tests.backend.market.helpers import make_client, submit

PASSWORD = "team member password"


@dataclass
class Member:
    """A portal account, signed in."""

    base: str
    worker_id: str
    token: str

    def call(self, method: str, path: str) -> httpx.Response:
        return httpx.request(method, f"{self.base}/api/portal{path}", timeout=10,
                             headers={"Authorization": f"Bearer {self.token}"})

    def hits(self) -> list[dict[str, Any]]:
        resp = self.call("GET", "/hits")
        assert resp.status_code == 200, resp.text
        return list(resp.json())

    def listed(self) -> list[str]:
        return [hit["hit_id"] for hit in self.hits()]


@pytest.fixture
def members(crowd_url: str) -> dict[str, Member]:
    """Two portal accounts an admin made, amy and ben."""
    with httpx.Client(base_url=crowd_url, timeout=10) as client:
        headers = admin_headers(client)
        found = {}
        for name in ("amy", "ben"):
            email = f"{name}@lab.example.org"
            made = client.post("/api/portal/workers", headers=headers,
                               json={"email": email, "password": PASSWORD})
            assert made.status_code == 200, made.text
            login = client.post("/api/portal/login", json={"email": email, "password": PASSWORD})
            assert login.status_code == 200, login.text
            found[name] = Member(crowd_url, made.json()["worker_id"], login.json()["access_token"])
    return found


@pytest.fixture
def provider(crowd_url: str) -> CrowdProvider:
    made = make(get_settings())
    assert isinstance(made, CrowdProvider) and made.name == "team"
    return made


def spec(key: str, reward_cents: int = 0, assignee: str | None = None, **changes: Any) -> UnitSpec:
    fields: dict[str, Any] = {
        "key": key, "task_id": 7, "title": "Hand joints: right hand, view cam0",
        "description": "Click each hand joint on a few frames.", "keywords": "hand",
        "page_url": "https://label.example.org/annotate/?task=T0K3N", "reward_cents": reward_cents,
        "places": 1, "lifetime_s": 3600, "allotted_s": 1800, "auto_approve_s": 86400,
        "expected_s": 600, "frame_height": 700, "note": "dexlabel task 7 round 1",
        "requirements": Requirements(assignee=assignee)}
    fields.update(changes)
    return UnitSpec(**fields)


def team_client(base: str) -> Any:
    team = team_market_requester(get_settings().signing_key)
    return make_client(base, (team.access_key, team.secret_key))


def test_a_unit_assigned_to_a_member_is_theirs_alone_and_pays_nothing_anywhere(
    provider: CrowdProvider, members: dict[str, Member], crowd_url: str
) -> None:
    amy, ben = members["amy"], members["ben"]
    assigned, open_ = provider.publish([
        spec("dxhit-7-1-assigned", reward_cents=40, assignee=amy.worker_id),
        spec("dxhit-8-1-open", task_id=8, note="dexlabel task 8 round 1")])
    assert (assigned.outcome, open_.outcome) == ("created", "created")
    assert [(h["hit_id"], h["assigned_to_me"]) for h in amy.hits()] == [
        (assigned.unit_id, True), (open_.unit_id, False)]
    assert [(h["hit_id"], h["assigned_to_me"]) for h in ben.hits()] == [(open_.unit_id, False)]
    assert ben.call("GET", f"/hits/{assigned.unit_id}").status_code == 404
    assert ben.call("POST", f"/hits/{assigned.unit_id}/accept").status_code == 403

    accepted = amy.call("POST", f"/hits/{assigned.unit_id}/accept")
    assert accepted.status_code == 200, accepted.text
    assignment_id = accepted.json()["assignment_id"]
    assert list(provider.submissions([assigned.unit_id])) == []  # held, not submitted
    assert submit(crowd_url, assignment_id, labels="ok").status_code == 200
    [record] = provider.submissions([assigned.unit_id])
    assert (record.assignment_id, record.worker_id, record.status) == (
        assignment_id, amy.worker_id, "submitted")
    state = provider.unit(assigned.unit_id)
    assert state is not None and (state.task_id, state.places, state.held, state.submitted,
                                  state.open) == (7, 1, 0, 1, True)

    provider.approve(assignment_id, "Thank you, clean joints.")
    provider.approve(assignment_id, None)  # approved already: not an error
    assert provider.submission(assignment_id).status == "approved"  # type: ignore[union-attr]
    order = BonusOrder(key="dxbonus-1", assignment_id=assignment_id, unit_id=assigned.unit_id,
                       worker_id=amy.worker_id, amount_cents=25, reason="careful work")
    assert not provider.bonus_paid(order)
    provider.pay_bonus(order)
    fees = provider.fees()
    assert (fees.provider, fees.reward_fee_cents(40), fees.bonus_fee_cents(25)) == ("team", 0, 0)

    market = team_client(crowd_url)
    assert market.get_account_balance()["AvailableBalance"] == "0.00"
    assert market.list_bonus_payments(AssignmentId=assignment_id)["BonusPayments"] == []
    history = amy.call("GET", "/assignments").json()
    assert [(a["status"], a["feedback"], a["reward"]) for a in history["assignments"]] == [
        ("Approved", "Thank you, clean joints.", "0.00")]
    assert history["earnings"]["paid"] == "0.00"


def test_publishing_again_recovers_the_unit_and_the_completion_is_the_portal(
    provider: CrowdProvider, members: dict[str, Member], crowd_url: str
) -> None:
    first = provider.publish([spec("dxhit-9-1-again", assignee=members["ben"].worker_id)])
    again = provider.publish([spec("dxhit-9-1-again", assignee=members["ben"].worker_id)])
    assert again[0].outcome == "recovered" and again[0].unit_id == first[0].unit_id
    assert members["ben"].listed() == [first[0].unit_id]
    completion = provider.completion(first[0].unit_id, "ANY")
    assert (completion.kind, completion.url) == ("portal", f"{crowd_url}/market/#/hits")


def test_a_reward_of_0_is_taken_for_team_units_and_refused_on_the_mturk_path(
    provider: CrowdProvider, crowd_url: str
) -> None:
    [unit] = provider.publish([spec("dxhit-10-1-free")])
    assert team_client(crowd_url).get_hit(HITId=unit.unit_id)["HIT"]["Reward"] == "0.00"
    mturk = requester.make_client(get_settings())  # the mturk path's account, same market
    with pytest.raises(requester.MarketplaceRefused, match=r"smallest reward, 0\.01"):
        requester.call(mturk, "create_hit", Title="t", Description="d", Reward="0.00",
                       MaxAssignments=1, LifetimeInSeconds=3600, AssignmentDurationInSeconds=600,
                       Question=external_question("https://label.example.org/annotate/", 700))


def test_an_assignee_without_a_portal_account_or_a_locale_is_refused_before_any_call(
    provider: CrowdProvider, members: dict[str, Member]
) -> None:
    with pytest.raises(ProviderRefused, match="no portal account") as refused:
        provider.publish([spec("dxhit-11-1-x", assignee="A0NOBODY")])
    assert refused.value.extra["fields"][0]["field"] == "assignee"
    with pytest.raises(ProviderRefused, match="locale"):
        provider.check_publish([spec("dxhit-11-1-y",
                                     requirements=Requirements(locales=("US",)))])
    assert members["amy"].listed() == []


def test_the_team_uses_the_built_in_marketplace_whatever_the_mturk_endpoint_says(
    crowd_url: str, monkeypatch: pytest.MonkeyPatch, members: dict[str, Member]
) -> None:
    monkeypatch.setenv("DEXLABEL_MTURK_ENDPOINT_URL", "https://mturk-requester.example.org")
    get_settings.cache_clear()
    [unit] = make(get_settings()).publish([spec("dxhit-12-1-builtin")])
    assert members["amy"].listed() == [unit.unit_id]


def test_the_team_account_is_the_marketplace_s_own_and_not_one_to_configure(
    monkeypatch: pytest.MonkeyPatch
) -> None:
    from pydantic import ValidationError

    from backend.config import TEAM_MARKET_ACCESS_KEY, Settings

    monkeypatch.setenv("DEXLABEL_ENV", "test")
    monkeypatch.delenv("DEXLABEL_MARKET_REQUESTERS", raising=False)
    settings = Settings()
    team = settings.market_accounts[TEAM_MARKET_ACCESS_KEY]
    assert team.unpaid and team.start_balance_cents == 0
    assert TEAM_MARKET_ACCESS_KEY not in settings.market_requester_accounts
    monkeypatch.setenv("DEXLABEL_MARKET_REQUESTERS", f"{TEAM_MARKET_ACCESS_KEY}:a-secret-of-mine")
    with pytest.raises(ValidationError, match="team crowd's own account"):
        Settings()


def test_places_closing_blocks_and_groups_act_on_the_members_lists(
    provider: CrowdProvider, members: dict[str, Member]
) -> None:
    amy, ben = members["amy"], members["ben"]
    [unit] = provider.publish([spec("dxhit-13-1-life")])
    provider.add_places(unit.unit_id, 1, "dxadd-13-1")
    with pytest.raises(ProviderError) as replayed:  # the same key adds nothing more
        provider.add_places(unit.unit_id, 1, "dxadd-13-1")
    assert replayed.value.reason == "replayed"
    state = provider.unit(unit.unit_id)
    assert state is not None and (state.places, state.open) == (2, True)

    provider.block(ben.worker_id, "left the lab")
    assert (amy.listed(), ben.listed()) == ([unit.unit_id], [])
    provider.unblock(ben.worker_id, None)
    assert ben.listed() == [unit.unit_id]

    provider.close(unit.unit_id)
    assert provider.unit(unit.unit_id).open is False  # type: ignore[union-attr]
    assert amy.listed() == []
    provider.extend(unit.unit_id, 3600)
    assert amy.listed() == [unit.unit_id]

    group = provider.training_group()
    assert provider.training_group() == group
    [gated] = provider.publish([spec("dxhit-14-1-gated", requirements=Requirements(group=group))])
    assert gated.unit_id not in ben.listed()
    provider.grant(ben.worker_id, group, 1, notify=False)
    assert gated.unit_id in ben.listed()
    provider.revoke(ben.worker_id, group, "training to redo")
    assert gated.unit_id not in ben.listed()
    assert provider.unit("3NOSUCHHIT0000000000000000000") is None
