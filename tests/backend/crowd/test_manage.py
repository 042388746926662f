"""The admin's view of the crowd (backend.crowd.manage): units with their places, holders and
states as extend, expire and add-places leave them; a unit's assignments with the portal
account behind each worker; closing work left "working" frees its place and keeps its labels;
the team's accounts with their decided work."""

from __future__ import annotations

from typing import Any

from sqlalchemy import select

from backend.annotation.models import Assignment, Task, Track
from backend.crowd.models import CrowdHit
from backend.db import session_scope


def _open_work(hit_id: str, worker_id: str) -> int:
    """The worker holds the unit on the marketplace and our page opened it, with a saved track;
    our assignment id."""
    from backend.annotation.service import start_assignment
    from tests.backend.market.helpers import accept

    market_id = accept(hit_id, worker_id)
    with session_scope() as session:
        task = session.get_one(Task, session.scalar(
            select(CrowdHit.task_id).where(CrowdHit.hit_id == hit_id)))
        ours = start_assignment(session, task, market_id, worker_id, hit_id)
        session.add(Track(assignment_id=ours.id, point_index=0, keyframes=[[0, 1.0, 2.0, 1]]))
        return ours.id


def test_units_show_places_holders_and_states_after_extend_expire_and_add(
    api: Any, hit_ids: list[str],
) -> None:
    account = api.post("/api/portal/workers", json={
        "email": "member@example.org", "password": "a long team password"})
    assert account.status_code == 200, account.text
    member = account.json()["worker_id"]
    _open_work(hit_ids[0], member)
    assert api.post(f"/api/crowd/hits/{hit_ids[1]}/expire").status_code == 200
    assert api.post(f"/api/crowd/hits/{hit_ids[2]}/assignments",
                    json={"count": 2}).status_code == 200

    units = {u["hit_id"]: u for u in api.get("/api/crowd/units").json()}
    assert set(units) == set(hit_ids)
    first, expired, grown = units[hit_ids[0]], units[hit_ids[1]], units[hit_ids[2]]
    assert (first["provider"], first["places"], first["holders"], first["state"]) == (
        "mturk", 1, 1, "open")
    assert (expired["state"], expired["holders"]) == ("expired", 0)
    assert expired["expired_at"] is not None
    assert (grown["places"], grown["state"], grown["reward"]) == (3, "open", "0.50")
    one_task = api.get(f"/api/crowd/units?task_id={first['task_id']}").json()
    assert [u["hit_id"] for u in one_task] == [hit_ids[0]]

    listed = api.get(f"/api/crowd/units/{hit_ids[0]}/assignments").json()
    assert [(a["worker_id"], a["account_email"], a["status"]) for a in listed] == [
        (member, "member@example.org", "working")]
    assert api.get("/api/crowd/units/NOSUCHHIT/assignments").status_code == 404

    team = api.get(f"/api/crowd/team?worker_id={member}").json()
    assert [(t["email"], t["approved"], t["rejected"]) for t in team] == [
        ("member@example.org", 0, 0)]
    assert api.get("/api/crowd/team?worker_id=ANOBODY").json() == []


def test_closing_work_left_working_frees_its_place_and_keeps_its_labels(
    api: Any, hit_ids: list[str],
) -> None:
    from backend.annotation.service import require_open_slot
    from backend.annotation.tokens import assignment_token

    ours = _open_work(hit_ids[0], "AWORKERWALKEDAWAY")
    closed = api.post(f"/api/crowd/assignments/{ours}/close")
    assert closed.status_code == 200, closed.text
    assert closed.json()["status"] == "closed"
    assert api.get("/api/crowd/units?task_id=0").status_code == 422  # 0 is no id
    units = {u["hit_id"]: u for u in api.get("/api/crowd/units").json()}
    assert units[hit_ids[0]]["holders"] == 0
    with session_scope() as session:
        require_open_slot(session, hit_ids[0], held=1, duration_s=3600)  # the place is free
        kept = session.get_one(Assignment, ours)
        assert kept.status == "closed"
        assert [t.keyframes for t in kept.tracks] == [[[0, 1.0, 2.0, 1]]]

    # The worker's page can no longer change or submit it.
    with session_scope() as session:
        kept = session.get_one(Assignment, ours)
        token = assignment_token(kept.task, kept)
    saved = api.put("/api/annotate/tracks", headers={"Authorization": f"Bearer {token}"},
                    json={"version": 0, "edit_count": 1, "working_time_s": 5.0, "tracks": []})
    assert saved.status_code == 409, saved.text
    assert "assignment is closed" in saved.json()["detail"]

    again = api.post(f"/api/crowd/assignments/{ours}/close")
    assert again.status_code == 409
    assert again.json()["detail"].startswith(f"assignment {ours} is closed")
    assert api.post("/api/crowd/assignments/999999/close").status_code == 404


def test_the_crowd_views_are_for_admins_only(crowd_url: str) -> None:
    import httpx

    for path in ("/api/crowd/units", "/api/crowd/team", "/api/crowd/providers"):
        assert httpx.get(crowd_url + path, timeout=30).status_code == 401
    assert httpx.post(crowd_url + "/api/crowd/assignments/1/close",
                      timeout=30).status_code == 401


def test_the_publish_form_offers_each_provider_with_the_setting_as_default(api: Any) -> None:
    got = api.get("/api/crowd/providers").json()
    assert got == {"default": "mturk", "choices": ["mturk", "prolific", "team"]}
