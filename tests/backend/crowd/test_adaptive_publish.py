"""Publishing views where the 3D needs them: against the built-in marketplace through boto3,
on a real database, with solve results stored as the solve stores them."""

from __future__ import annotations

import io
import uuid
from datetime import UTC, datetime
from typing import Any

import cv2
import numpy as np
import pytest
from sqlalchemy import select
from typer.testing import CliRunner

from backend.annotation.models import Task
from backend.captures.models import Camera
from backend.config import InvalidSettings, get_settings
from backend.crowd import flows
from backend.crowd.client import make_client
from backend.crowd.models import CrowdHit, PublishPlan
from backend.crowd.schemas import PublishOptions
from backend.db import session_scope
from tests.worker.geometry.test_view_choice import TestInitialViews, ring

# Views 0, 2 and 3 pin a target at the origin best (tests/worker/geometry/test_view_choice).
AZIMUTHS = TestInitialViews.AZIMUTHS
INITIAL = ["cam0", "cam2", "cam3"]
FRAMES = 6
ADAPTIVE = PublishOptions(min_approval_rate=None, policy="adaptive")


def make_rig_sequence() -> int:
    """A sequence of 4 cameras on a ring around the origin, a right hand and a grasped object
    at the origin, one task per view and target; the sequence id."""
    from backend.annotation.models import Task
    from backend.captures.models import Camera, Hand, SceneObject, Sequence, Subject

    with session_scope() as session:
        sequence = Sequence(subject=Subject(name=f"subject-{uuid.uuid4().hex[:6]}"),
                            name="grasp", storage_uid=uuid.uuid4().hex, num_frames=FRAMES,
                            source_kind="images", fingerprint="0" * 64)
        session.add(sequence)
        session.flush()
        hand = Hand(sequence_id=sequence.id, index=0, side="right")
        obj = SceneObject(sequence_id=sequence.id, index=0, ycb_id=6, name="006_mustard_bottle",
                          mesh_key="meshes/mustard.obj", num_vertices=8, num_faces=12,
                          grasped=True, initial_pose=[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]])
        session.add_all([hand, obj])
        session.flush()
        for view, model in enumerate(ring(AZIMUTHS)):
            camera = Camera(sequence_id=sequence.id, serial=f"cam{view}", view_index=view,
                            width=640, height=480, fx=600.0, fy=600.0, ppx=320.0, ppy=240.0,
                            distortion=[0.0] * 5, extrinsics=model.T_cam_to_world.tolist())
            session.add(camera)
            session.flush()
            session.add_all([
                Task(sequence_id=sequence.id, camera_id=camera.id, kind="hand",
                     target_key="hand:0", hand_id=hand.id, num_points=21),
                Task(sequence_id=sequence.id, camera_id=camera.id, kind="object",
                     target_key="object:0", object_id=obj.id, num_points=2)])
        return sequence.id


def published(sequence_id: int) -> dict[str, dict[str, str | None]]:
    """Per target, the published views (camera serials) and each one's reason."""
    from backend.annotation.models import Task
    from backend.captures.models import Camera

    out: dict[str, dict[str, str | None]] = {}
    with session_scope() as session:
        for target, serial, reason in session.execute(
                select(Task.target_key, Camera.serial, CrowdHit.reason)
                .join(Task, Task.id == CrowdHit.task_id).join(Camera, Camera.id == Task.camera_id)
                .where(Task.sequence_id == sequence_id, CrowdHit.hit_id.is_not(None))):
            out.setdefault(target, {})[serial] = reason
    return out


def store_solve(sequence_id: int, hand_confidence: np.ndarray,
                hand_flags: list[str] | None = None) -> int:
    """A done solve run of the sequence with its outputs stored as backend.solve.results
    stores them: the hand's per-frame confidence as given, the object fully trusted."""
    from backend.solve.models import SolveRun
    from backend.solve.results import result_key
    from backend.storage import get_storage

    joints = np.zeros((FRAMES, 21, 3))
    joints += np.linspace(-0.02, 0.02, 21)[None, :, None]
    arrays = {
        "labelled": np.ones(FRAMES, bool),
        "hand_joints": joints, "hand_confidence": np.asarray(hand_confidence, float),
        "hand_flags": np.asarray(hand_flags or [""] * FRAMES, str),
        "object_poses": np.tile(np.eye(4)[:3], (1, FRAMES, 1, 1)),
        "object_names": np.asarray(["006_mustard_bottle"]),
        "object_confidence": np.ones((1, FRAMES)),
        "object_flags": np.full((1, FRAMES), "", str),
    }
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)  # type: ignore[arg-type]
    with session_scope() as session:
        run = SolveRun(sequence_id=sequence_id, optimiser="default", params={}, status="done",
                       timings={}, num_frames=FRAMES, num_views=len(AZIMUTHS),
                       finished_at=datetime.now(UTC))
        session.add(run)
        session.flush()
        sequence_uid = uuid.uuid4().hex
        run.result_key = result_key(sequence_uid, run.id)
        get_storage().put_bytes(run.result_key, buf.getvalue())
        return run.id


def test_adaptive_publishes_first_the_widest_baseline_views_of_each_target(
    crowd_url: str,
) -> None:
    from backend.labels import accepted_digest
    from backend.progress.service import sequence_progress

    sequence_id = make_rig_sequence()
    with session_scope() as session:
        result = flows.publish(session, make_client(get_settings()), ADAPTIVE, sequence_id)
    assert result.created == 6 and result.cost.hits == 6
    units = published(sequence_id)
    assert {target: sorted(views) for target, views in units.items()} == {
        "hand:0": INITIAL, "object:0": INITIAL}
    assert set(units["hand:0"].values()) == {
        "initial: widest baselines (3 of 4 views)"}
    with session_scope() as session:
        # The solve waits for the published views only.
        assert accepted_digest(session, sequence_id) == (None, 6)
        progress = sequence_progress(session, sequence_id)
        again = flows.publish(session, make_client(get_settings()), ADAPTIVE, sequence_id)
    assert again.created == 0  # the held views wait for a solve that needs them
    assert progress.publish_policy == "adaptive" and progress.held == 2
    held = {(t.serial, t.target_key) for t in progress.tasks if t.held}
    assert held == {("cam1", "hand:0"), ("cam1", "object:0")}
    assert all(t.publish_reason and t.publish_reason.startswith("initial: widest baselines")
               for t in progress.tasks if not t.held)


def store_depth(sequence_id: int, hand_mm: dict[str, tuple[float, int]]) -> None:
    """Depth maps (a table at 1.5 m, a 60 px square hand at ``mm`` whose left edge starts at
    ``x0`` px and moves 8 px a frame) for each camera serial of ``hand_mm``: serial -> (mm,
    x0), stored as an import stores them (16-bit PNG, one Frame row per frame)."""
    from backend.captures.models import Camera, Frame
    from backend.storage import get_storage

    storage = get_storage()
    with session_scope() as session:
        for camera in session.scalars(select(Camera).where(Camera.sequence_id == sequence_id)):
            mm, x0 = hand_mm[camera.serial]
            for f in range(FRAMES):
                depth = np.full((camera.height, camera.width), 1500, np.uint16)
                left = x0 + 8 * f
                depth[200:260, max(left, 0):max(left + 60, 0)] = mm
                key = f"test-depth/{sequence_id}/{camera.serial}/{f:06d}.png"
                storage.put_bytes(key, cv2.imencode(".png", depth)[1].tobytes(), "image/png")
                session.add(Frame(camera_id=camera.id, index=f, color_key=f"{key}.jpg",
                                  color_bytes=1, depth_key=key))


def test_a_hands_start_view_is_published_first_and_the_rest_widen_from_it(
    crowd_url: str,
) -> None:
    from backend.market.workers import list_available_hits

    sequence_id = make_rig_sequence()
    # cam1 keeps the hand whole and farthest; cam0 (of the widest pair) cuts it on the first
    # frame; cam2 and cam3 keep it whole but nearer.
    store_depth(sequence_id, {"cam0": (1100.0, -30), "cam1": (900.0, 100),
                              "cam2": (700.0, 100), "cam3": (800.0, 300)})
    with session_scope() as session:
        result = flows.publish(session, make_client(get_settings()), ADAPTIVE, sequence_id)
    assert result.created == 6
    units = published(sequence_id)
    # Started from cam1 (15 degrees), the baselines widen to 100 and 175 degrees
    # (tests/worker/geometry/test_view_choice); the object keeps its widest pair.
    assert units["hand:0"] == {"cam1": "initial: worked first, the hand whole in view (3 of 4 "
                                       "views)",
                               "cam2": "initial: widest baselines (3 of 4 views)",
                               "cam3": "initial: widest baselines (3 of 4 views)"}
    assert sorted(units["object:0"]) == INITIAL
    with session_scope() as session:
        by_hit = {hit_id: (target, serial) for hit_id, target, serial in session.execute(
            select(CrowdHit.hit_id, Task.target_key, Camera.serial)
            .join(Task, Task.id == CrowdHit.task_id).join(Camera, Camera.id == Task.camera_id)
            .where(Task.sequence_id == sequence_id))}
        listed = [by_hit[v.hit.hit_id] for v in list_available_hits(
            session, "A1NEWWORKER", datetime.now(UTC)) if v.hit.hit_id in by_hit]
    # The crowd's list (oldest first) opens with the hand's start view.
    assert next(serial for target, serial in listed if target == "hand:0") == "cam1"


def test_a_view_whose_depth_cannot_be_read_is_not_a_start_view(crowd_url: str) -> None:
    from backend.captures.models import Frame
    from backend.storage import get_storage

    sequence_id = make_rig_sequence()
    store_depth(sequence_id, {"cam0": (1100.0, -30), "cam1": (900.0, 100),
                              "cam2": (700.0, 100), "cam3": (800.0, 300)})
    with session_scope() as session:
        keys = [key for key in session.scalars(select(Frame.depth_key).join(Camera).where(
            Camera.sequence_id == sequence_id, Camera.serial.in_(("cam1", "cam3")))
            .order_by(Camera.serial, Frame.index)) if key]
    get_storage().put_bytes(keys[0], b"not a png", "image/png")  # cam1, frame 0
    get_storage().delete_prefix(keys[-1])  # cam3, the last frame
    with session_scope() as session:
        result = flows.publish(session, make_client(get_settings()), ADAPTIVE, sequence_id)
    assert result.created == 6
    hand = published(sequence_id)["hand:0"]
    assert hand["cam2"] == "initial: worked first, the hand whole in view (3 of 4 views)"


def test_without_a_view_that_keeps_the_hand_whole_the_widest_pair_leads(
    crowd_url: str,
) -> None:
    sequence_id = make_rig_sequence()
    store_depth(sequence_id, dict.fromkeys(("cam0", "cam1", "cam2", "cam3"), (900.0, -30)))
    with session_scope() as session:
        flows.publish(session, make_client(get_settings()), ADAPTIVE, sequence_id)
    units = published(sequence_id)
    assert sorted(units["hand:0"]) == INITIAL
    assert set(units["hand:0"].values()) == {"initial: widest baselines (3 of 4 views)"}


def test_every_view_publishes_every_view_at_once_as_before(crowd_url: str) -> None:
    sequence_id = make_rig_sequence()
    with session_scope() as session:
        result = flows.publish(session, make_client(get_settings()),
                               PublishOptions(min_approval_rate=None), sequence_id)
        plans = session.scalars(select(PublishPlan)).all()
    assert result.created == 8 and plans == []
    units = published(sequence_id)
    assert {t: sorted(v) for t, v in units.items()} == {
        "hand:0": ["cam0", "cam1", "cam2", "cam3"], "object:0": ["cam0", "cam1", "cam2", "cam3"]}
    assert {r for views in units.values() for r in views.values()} == {None}


def test_no_view_is_added_while_the_solve_is_confident(crowd_url: str) -> None:
    from backend import pipeline

    sequence_id = make_rig_sequence()
    with session_scope() as session:
        flows.publish(session, make_client(get_settings()), ADAPTIVE, sequence_id)
    run_id = store_solve(sequence_id, np.full(FRAMES, 0.9))
    done = pipeline.publish_views(run_id)
    assert done["published"] == 0 and "no more views needed" in done["message"]
    assert sum(len(v) for v in published(sequence_id).values()) == 6


def test_a_view_is_added_with_its_reason_where_frames_are_below_the_target(
    crowd_url: str,
) -> None:
    from backend import pipeline

    sequence_id = make_rig_sequence()
    with session_scope() as session:
        flows.publish(session, make_client(get_settings()), ADAPTIVE, sequence_id)
    # Frames 2-4 below 0.5, frame 5 flagged: 2 of 6 confident, under the share of 0.9.
    flags = ["", "", "", "", "", "fewer than 2 views decided this frame"]
    run_id = store_solve(sequence_id, np.array([0.9, 0.8, 0.2, 0.3, 0.1, 0.9]), flags)
    done = pipeline.publish_views(run_id)
    assert done["published"] == 1
    units = published(sequence_id)
    assert sorted(units["object:0"]) == INITIAL  # the object is confident: nothing added
    assert units["hand:0"]["cam1"] == (
        "frames 2-5 below confidence 0.5 or flagged after views cam0, cam2, cam3")
    assert pipeline.publish_views(run_id)["published"] == 0  # a re-run adds nothing more
    # Every view of the hand published: a later unsure solve has nothing left to add.
    later = store_solve(sequence_id, np.zeros(FRAMES))
    assert pipeline.publish_views(later)["published"] == 0


def test_publishing_again_with_every_view_publishes_the_held_views(crowd_url: str) -> None:
    from backend.labels import accepted_digest

    sequence_id = make_rig_sequence()
    with session_scope() as session:
        flows.publish(session, make_client(get_settings()), ADAPTIVE, sequence_id)
    with session_scope() as session:
        result = flows.publish(session, make_client(get_settings()),
                               PublishOptions(min_approval_rate=None, policy="every-view"),
                               sequence_id)
    assert result.created == 2
    with session_scope() as session:
        assert accepted_digest(session, sequence_id) == (None, 8)
    assert all(len(views) == 4 for views in published(sequence_id).values())


@pytest.mark.parametrize(("body", "field"), [
    ({"policy": "sometimes"}, "policy"), ({"confidence": 0}, "confidence"),
    ({"confident_share": 1.5}, "confident_share"), ({"initial_views": 1}, "initial_views"),
])
def test_bad_policy_values_are_refused_naming_the_field(
    api: Any, body: dict[str, Any], field: str,
) -> None:
    resp = api.post("/api/crowd/publish", json={"min_approval_rate": None, **body})
    assert resp.status_code == 422, resp.text
    assert [f["field"] for f in resp.json()["fields"]] == [field]
    assert resp.json()["detail"].startswith(f"{field}: ")


def test_the_cli_refuses_a_bad_policy_and_publishes_adaptively(crowd_url: str) -> None:
    from backend.cli import app

    sequence_id = make_rig_sequence()
    runner = CliRunner()
    bad = runner.invoke(app, ["publish", "--sequence", str(sequence_id), "--policy", "some"])
    assert bad.exit_code == 2 and "policy: Input should be 'every-view' or 'adaptive'" \
        in bad.output, bad.output
    bad = runner.invoke(app, ["publish", "--sequence", str(sequence_id), "--policy",
                              "adaptive", "--confidence", "1.5"])
    assert bad.exit_code == 2 and "confidence: Input should be less than or equal to 1" \
        in bad.output, bad.output
    out = runner.invoke(app, ["publish", "--sequence", str(sequence_id), "--policy", "adaptive",
                              "--min-approval-rate", "0", "--dry-run"])
    assert out.exit_code == 0 and "6 HITs x 1 assignment(s)" in out.output, out.output


def test_a_bad_policy_setting_is_named_when_the_settings_load(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setenv("DEXLABEL_PUBLISH_POLICY", "sometimes")
    monkeypatch.setenv("DEXLABEL_PUBLISH_CONFIDENT_SHARE", "0")
    get_settings.cache_clear()
    try:
        with pytest.raises(InvalidSettings) as caught:
            get_settings()
    finally:
        monkeypatch.undo()
        get_settings.cache_clear()
    lines = caught.value.detail.splitlines()
    assert "DEXLABEL_PUBLISH_POLICY: Input should be 'every-view' or 'adaptive'" in lines
    assert "DEXLABEL_PUBLISH_CONFIDENT_SHARE: Input should be greater than 0" in lines


def submit_provisional(sequence_id: int, serials: list[str], target: str = "hand:0",
                       outcome: str | None = "approve") -> list[int]:
    """Submitted work on the target's tasks in ``serials``, each left provisional by QC with
    ``outcome`` (None: not scored yet; "reject": rejected); the assignment ids."""
    from backend.annotation.models import Assignment, Task
    from backend.captures.models import Camera

    ids = []
    with session_scope() as session:
        tasks = session.scalars(select(Task).join(Camera, Camera.id == Task.camera_id).where(
            Task.sequence_id == sequence_id, Task.target_key == target,
            Camera.serial.in_(serials))).all()
        for task in tasks:
            assignment = Assignment(
                task_id=task.id, worker_id=f"W{uuid.uuid4().hex[:10].upper()}",
                external_id=uuid.uuid4().hex,
                status="rejected" if outcome == "reject" else "submitted",
                submitted_at=datetime.now(UTC))
            session.add(assignment)
            session.flush()
            ids.append(assignment.id)
    if outcome is not None:
        score_provisional(ids, outcome)
    return ids


def score_provisional(assignment_ids: list[int], outcome: str = "approve") -> None:
    """QC's provisional report on each assignment: too few views to compare it with."""
    from backend.annotation.models import Assignment
    from backend.quality.models import QCReport

    with session_scope() as session:
        for assignment_id in assignment_ids:
            a = session.get_one(Assignment, assignment_id)
            session.add(QCReport(assignment_id=a.id, task_id=a.task_id,
                                 sequence_id=a.task.sequence_id, target_key=a.task.target_key,
                                 worker_id=a.worker_id, metrics={}, outcome=outcome,
                                 provisional=True, views=2,
                                 reasons=["provisional: too few views"]))


def test_work_qc_cannot_judge_for_want_of_views_gets_one_more_view(crowd_url: str) -> None:
    """Published 2 views first: once both are submitted and QC could not compare them with a
    third, the next view goes out saying why; not before, and not twice."""
    from backend import pipeline

    sequence_id = make_rig_sequence()
    with session_scope() as session:
        flows.publish(session, make_client(get_settings()),
                      ADAPTIVE.model_copy(update={"initial_views": 2}), sequence_id)
    first = sorted(published(sequence_id)["hand:0"])
    assert len(first) == 2
    submit_provisional(sequence_id, first[:1])
    # One published view is still being worked: its work may let QC decide.
    assert pipeline.publish_views_to_compare(sequence_id, "hand:0")["published"] == 0
    # Its work rejected (the task re-opened): still to come.
    submit_provisional(sequence_id, first[1:], outcome="reject")
    assert pipeline.publish_views_to_compare(sequence_id, "hand:0")["published"] == 0
    # Submitted again, not scored yet (its QC is still to run): nothing either.
    unscored = submit_provisional(sequence_id, first[1:], outcome=None)
    assert pipeline.publish_views_to_compare(sequence_id, "hand:0")["published"] == 0
    score_provisional(unscored)
    done = pipeline.publish_views_to_compare(sequence_id, "hand:0")
    assert done["published"] == 1, done
    units = published(sequence_id)
    (added,) = set(units["hand:0"]) - set(first)
    assert units["hand:0"][added] == (
        f"QC compares each label with at least 3 views: the work in {', '.join(first)} "
        "waits for another view")
    assert sorted(units["object:0"]) == first  # the object's views wait for their own need
    # The third view is published and not yet submitted: nothing more.
    assert pipeline.publish_views_to_compare(sequence_id, "hand:0")["published"] == 0
    assert len(published(sequence_id)["hand:0"]) == 3
