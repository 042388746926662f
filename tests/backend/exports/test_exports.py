"""Label export end to end on the small solved synthetic capture (3 views x 6 frames, 2 objects):
REST jobs and downloads, the CLI, the DexYCB round trip through the importer, the JSON schema,
and the refusals."""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path

import jsonschema
import numpy as np
import pytest
import yaml
from fastapi.testclient import TestClient
from sqlalchemy import select
from typer.testing import CliRunner

from backend.annotation.models import Assignment, Task, Track
from backend.captures.flows import import_path
from backend.captures.layout import read_sequence
from backend.captures.models import Camera, Frame, Sequence, Subject
from backend.cli import app
from backend.config import get_settings
from backend.db import session_scope
from backend.jobs.models import Job
from backend.jobs.runner import execute
from backend.pipeline.deletion import delete_sequence_rows as delete_sequence
from backend.solve.results import decode_result, hand_trust
from backend.solve.service import current_run
from backend.storage import get_storage
from tests.backend.exports import export_checks
from tests.backend.solve.test_solve_api import _solve, approved, sequence  # noqa: F401
from worker.formats import dexycb, dexycb_flags, jsonfmt
from worker.geometry.transforms import invert_pose, transform_points

pytestmark = pytest.mark.slow


def _export(client: TestClient, headers: dict, body: dict) -> dict:
    resp = client.post("/api/exports", json=body, headers=headers)
    assert resp.status_code == 200, resp.text
    job = resp.json()
    assert job["status"] == "queued" and job["download_url"] is None
    with session_scope() as s:
        key = s.get_one(Job, job["id"]).key
    execute(key)
    state = client.get(f"/api/exports/{job['id']}", headers=headers).json()
    assert state["status"] == "done", state
    assert state["progress"]["done"] == state["progress"]["total"] or state["progress"]
    return state


def _download(client: TestClient, headers: dict, state: dict) -> zipfile.ZipFile:
    resp = client.get(state["download_url"], headers=headers)
    assert resp.status_code == 200 and resp.headers["content-type"] == "application/zip"
    return zipfile.ZipFile(io.BytesIO(resp.content))


def _cameras(seq_id: int) -> dict[str, dict]:
    with session_scope() as s:
        cams = s.scalars(select(Camera).where(Camera.sequence_id == seq_id)).all()
        return {c.serial: {"K": [c.fx, c.fy, c.ppx, c.ppy], "size": (c.width, c.height),
                           "dist": list(c.distortion), "T": np.asarray(c.extrinsics),
                           "frames": len(c.frames)} for c in cams}


def _check_labels(root: Path, seq_id: int, cameras: dict[str, dict]) -> None:
    """Exported labels equal the stored solve (float32) and joint_2d is K-only pinhole."""
    with session_scope() as s:
        run = current_run(s, seq_id)
        assert run is not None and run.result_key
        key = run.result_key
    arrays = decode_result(get_storage().get_bytes(key))
    seq_dir = next(root.glob(dexycb.META_GLOB)).parent
    pose = np.load(seq_dir / dexycb.POSE_FILE)
    labelled = arrays["labelled"]
    assert np.array_equal(pose["pose_m"][labelled, 0],
                          arrays["hand_pose_m"][labelled].astype(np.float32))
    distorted = 0
    for serial, cam in cameras.items():
        distorted += any(cam["dist"])
        K = np.array([[cam["K"][0], 0, cam["K"][2]], [0, cam["K"][1], cam["K"][3]], [0, 0, 1]])
        w2c = invert_pose(cam["T"])
        for f in range(cam["frames"]):
            lab = np.load(seq_dir / serial / dexycb.labels_file(f))
            assert lab["seg"].dtype == np.uint8 and lab["seg"].shape == cam["size"][::-1]
            if not labelled[f]:
                # DexYCB's toolkit: joint_3d and joint_2d all -1, pose_m all 0.
                assert (lab["joint_3d"] == -1).all() and (lab["joint_2d"] == -1).all()
                assert (lab["pose_m"] == 0).all()
                continue
            joints = transform_points(w2c, arrays["hand_joints"][f])
            assert np.array_equal(lab["joint_3d"][0], joints.astype(np.float32))
            poses = np.einsum("ij,ojk->oik", w2c[:, :3], arrays["object_poses"][:, f])
            poses[:, :, 3] += w2c[:, 3]
            np.testing.assert_allclose(lab["pose_y"], poses, atol=2e-6)
            j3 = lab["joint_3d"][0].astype(np.float64)
            pinhole = (j3 @ K.T)[:, :2] / (j3 @ K.T)[:, 2:]
            assert np.abs(pinhole - lab["joint_2d"][0]).max() < 0.01
            assert (lab["seg"] == dexycb.HAND_SEG_VALUE).sum() > 50
    assert distorted >= 1, "the capture should have a camera with distortion"
    meta = (seq_dir / dexycb.META_FILE).read_text()
    assert dexycb.META_UNDISTORTED in meta


def test_dexycb_export_round_trips_through_the_importer_with_pinhole_labels(
    client: TestClient, admin_headers: dict, approved: int, tmp_path: Path  # noqa: F811
) -> None:
    run = _solve(client, admin_headers, approved, {"optimiser": "default"})
    assert run["status"] == "done"
    state = _export(client, admin_headers, {"format": "dexycb", "sequences": [approved],
                                            "options": {"frames": "copy", "split": "s0"}})
    assert state["result"]["frames"] == 18 and "path" not in state["result"]
    root = tmp_path / "export"
    _download(client, admin_headers, state).extractall(root)
    assert (root / "splits" / "s0_train.txt").read_text().count("\n") == 3
    cameras = _cameras(approved)
    _check_labels(root, approved, cameras)
    plan = read_sequence(next(root.glob(dexycb.META_GLOB)).parent)
    with session_scope() as s:
        seq = s.get_one(Sequence, approved)
        objects = [(o.ycb_id, o.name, o.grasped, o.num_vertices) for o in seq.objects]
        name = (seq.subject.name, seq.name, seq.num_frames)
        delete_sequence(s, approved, force=True)
    assert [(o.ycb_id, o.name, o.grasped, o.num_vertices) for o in plan.objects] == objects
    new_id = import_path(root)[0].sequence_id
    again = _cameras(new_id)
    assert set(again) == set(cameras)
    for serial, cam in cameras.items():
        assert again[serial]["K"] == cam["K"] and again[serial]["size"] == cam["size"]
        assert again[serial]["frames"] == cam["frames"]
        np.testing.assert_allclose(again[serial]["T"], cam["T"], atol=1e-12)
        assert not any(again[serial]["dist"])  # undistorted: pinhole frames
    with session_scope() as s:
        seq = s.get_one(Sequence, new_id)
        assert (seq.subject.name, seq.name, seq.num_frames) == name
        assert [(o.ycb_id, o.name, o.grasped, o.num_vertices) for o in seq.objects] == objects
        assert s.scalar(select(Frame.depth_key).join(Camera)
                        .where(Camera.sequence_id == new_id).limit(1))


def _unlabelled_sequence() -> int:
    """A sequence with no tasks yet (a capture imported after the labelling)."""
    with session_scope() as s:
        subject = Subject(name="late-subject")
        s.add(subject)
        s.flush()
        seq = Sequence(subject_id=subject.id, name="late", storage_uid="late-uid",
                       num_frames=6, fps=30.0, source_kind="images", fingerprint="0" * 64)
        s.add(seq)
        s.flush()
        return seq.id


def _mark_first_hand_keyframe_tracked(sequence_id: int) -> int:
    """Stores the first keyframe of point 0 of the first approved hand assignment as an accepted
    tracking proposal; returns that assignment's id."""
    with session_scope() as s:
        assignment = s.scalars(
            select(Assignment).join(Task, Assignment.task_id == Task.id)
            .where(Task.sequence_id == sequence_id, Task.kind == "hand",
                   Assignment.status == "approved").order_by(Assignment.id)).first()
        assert assignment is not None
        track = next(t for t in assignment.tracks if t.point_index == 0)
        first, *rest = track.keyframes
        track.keyframes = [list(first[:4]) + ["tracked"], *rest]
        return assignment.id


def test_exports_read_back_in_each_format_s_own_reader_as_the_stored_labels_and_solve(
    client: TestClient, admin_headers: dict, approved: int, tmp_path: Path  # noqa: F811
) -> None:
    _solve(client, admin_headers, approved, {"optimiser": "default"})
    unlabelled = _unlabelled_sequence()
    tracked_id = _mark_first_hand_keyframe_tracked(approved)
    state = _export(client, admin_headers, {"format": "json", "all": True,
                                            "include": "submitted"})
    # The whole project: the sequence without labels is left out, by name.
    assert state["sequence_ids"] == [approved]
    skipped = f"sequence {unlabelled} (late-subject/late) has no submitted labels to export"
    assert state["skipped"] == [skipped]
    archive = _download(client, admin_headers, state)
    [name] = archive.namelist()
    document = json.loads(archive.read(name))
    jsonschema.validate(document, jsonfmt.schema())
    assert document["include"] == "submitted" and len(document["work"]) == 9
    assert len(document["solve"]["frames"]) == 6 and len(document["solve"]["consensus"]) == 3
    hand = next(w for w in document["work"] if w["kind"] == "hand")
    assert len(hand["points"]) == 21 and len(hand["points"][0]["dense"]) == 6
    stored = next(w for w in export_checks.accepted_work(approved)
                  if w.assignment_id == hand["assignment_id"])
    # Every exported keyframe is the stored row with its source spelled out ("placed" when the
    # stored row leaves it out).
    assert [p["keyframes"] for p in hand["points"]] == [
        [row[:4] + [row[4] if len(row) == 5 else "placed"] for row in point]
        for point in stored.keyframes]
    sources = [k[4] for w in document["work"] for p in w["points"] for k in p["keyframes"]]
    assert sources.count("tracked") == 1 and set(sources) == {"placed", "tracked"}
    marked = next(w for w in document["work"] if w["assignment_id"] == tracked_id)
    assert marked["points"][0]["keyframes"][0][4] == "tracked"
    marked["points"][0]["keyframes"][0][4] = "guessed"
    with pytest.raises(jsonschema.ValidationError):  # the schema names the allowed sources
        jsonschema.validate(document, jsonfmt.schema())

    state = _export(client, admin_headers, {"format": "coco", "sequences": [approved]})
    export_checks.check_coco(_download(client, admin_headers, state), tmp_path, approved)
    state = _export(client, admin_headers, {"format": "bop", "sequences": [approved],
                                            "options": {"frames": "copy"}})
    export_checks.check_bop(_download(client, admin_headers, state), approved)
    state = _export(client, admin_headers, {"format": "cvat", "sequences": [approved]})
    export_checks.check_cvat(_download(client, admin_headers, state), approved)


def test_bad_export_requests_are_refused_naming_the_problem(
    client: TestClient, admin_headers: dict, sequence: int, tmp_path: Path  # noqa: F811
) -> None:
    def refused(body: dict, status: int, words: str) -> None:
        resp = client.post("/api/exports", json=body, headers=admin_headers)
        assert resp.status_code == status and words in resp.json()["detail"], resp.text

    refused({"format": "pascal", "all": True}, 422, "format must be one of dexycb")
    refused({"format": "json", "sequences": [sequence]}, 409, "has no accepted labels")
    refused({"format": "json", "all": True}, 409,
            "no sequence of the project can be exported as json: sequence")
    refused({"format": "dexycb", "sequences": [sequence]}, 409, "has no finished solve")
    refused({"format": "json", "sequences": [99999]}, 404, "sequence 99999 does not exist")
    refused({"format": "json"}, 422, "either sequences")
    refused({"format": "json", "sequences": []}, 422, "at least one sequence")
    refused({"format": "coco", "all": True, "include": "submitted"}, 422, "accepted labels only")
    refused({"format": "json", "all": True, "options": {"frames": "copy"}}, 422,
            "options.frames is not an option of the json format")
    refused({"format": "dexycb", "all": True, "options": {"frames": "link"}}, 422,
            "options.frames=link is for `dexlabel export --link-frames`")
    assert client.post("/api/exports", json={"format": "json", "all": True}).status_code == 401
    assert client.get("/api/exports/1").status_code == 401
    assert client.get("/api/exports/1/download").status_code == 401
    assert client.get("/api/exports/77", headers=admin_headers).status_code == 404
    runner = CliRunner()
    out = tmp_path / "x.zip"
    out.write_bytes(b"")
    result = runner.invoke(app, ["export", str(sequence), "--format", "json", "--out", str(out)])
    assert result.exit_code == 2 and "exists" in result.output
    result = runner.invoke(app, ["export", str(sequence), "--format", "bop", "--out",
                                 str(tmp_path / "y.zip")])
    assert result.exit_code == 2 and "has no finished solve" in result.output
    assert not (tmp_path / "y.zip").exists()
    for args, words in (
            (["--format", "pascal", "--out", str(tmp_path / "p.zip")], "format must be one of"),
            (["--format", "json", "--out", str(tmp_path / "missing" / "j.zip")],
             "folder " + str(tmp_path / "missing") + " does not exist"),
            (["--format", "json", "--out", str(tmp_path / "j.tar.gz")], "is none of them")):
        result = runner.invoke(app, ["export", str(sequence), *args])
        assert result.exit_code == 2 and words in result.output, result.output
    assert not (tmp_path / "missing").exists() and not (tmp_path / "j.tar.gz").exists()
    assert not list(tmp_path.glob(".*partial*"))


def test_cli_export_writes_a_tar_with_progress(
    client: TestClient, admin_headers: dict, approved: int, tmp_path: Path  # noqa: F811
) -> None:
    out = tmp_path / "labels.tar"
    result = CliRunner().invoke(app, ["export", str(approved), "--format", "cvat", "--out",
                                      str(out)])
    assert result.exit_code == 0, result.output
    assert "view 3 of 3" in result.output and out.is_file()
    import tarfile
    with tarfile.open(out) as tar:
        assert len([n for n in tar.getnames() if n.endswith(".xml")]) == 3


def test_a_failing_export_leaves_no_archive_and_says_why(
    client: TestClient, admin_headers: dict, approved: int, tmp_path: Path  # noqa: F811
) -> None:
    # A stored track that no longer checks (a keyframe past the clip) in the last view: the
    # export fails after writing the first views.
    with session_scope() as s:
        last_camera = max(s.scalars(select(Camera.id).where(Camera.sequence_id == approved)))
        track = s.scalars(select(Track).join(Assignment).join(Task)
                          .where(Task.camera_id == last_camera)).first()
        assert track is not None
        track.keyframes = [[99, 10.0, 10.0, 1]]
    resp = client.post("/api/exports", json={"format": "cvat", "sequences": [approved]},
                       headers=admin_headers)
    job = resp.json()
    with session_scope() as s:
        key = s.get_one(Job, job["id"]).key
    execute(key)
    state = client.get(f"/api/exports/{job['id']}", headers=admin_headers).json()
    assert state["status"] in ("retrying", "failed") and "frame" in state["error"]
    assert state["download_url"] is None
    resp = client.get(f"/api/exports/{job['id']}/download", headers=admin_headers)
    assert resp.status_code == 409 and "can be downloaded once it is done" in resp.text
    exports = get_settings().var_dir / "exports"
    assert not exports.exists() or not list(exports.iterdir())
    (tmp_path / "out").mkdir()
    out = tmp_path / "out" / "labels.zip"
    result = CliRunner().invoke(app, ["export", str(approved), "--format", "cvat", "--out",
                                      str(out)])
    assert result.exit_code == 1 and "the export failed" in result.output, result.output
    assert "nothing was written at" in result.output and "Traceback" not in result.output
    assert list((tmp_path / "out").iterdir()) == []


HAND_REASON = "hand frame not pinned down: interpolated in every view"
OBJECT_REASON = "landmarks 14.0 px off in 2 views"


def _flag_stored_result(sequence_id: int, hand_frame: int, object_frame: int
                        ) -> dict[str, np.ndarray]:
    """Rewrites the current run's stored result with the hand flagged at ``hand_frame`` and
    object 0 at ``object_frame`` (as the solve writes its flags); returns the arrays."""
    with session_scope() as s:
        run = current_run(s, sequence_id)
        assert run is not None and run.result_key
        key = run.result_key
    arrays = decode_result(get_storage().get_bytes(key))
    frames = len(arrays["labelled"])
    assert arrays["labelled"][hand_frame]
    hand_flags = np.full(frames, "", dtype=object)
    hand_flags[hand_frame] = HAND_REASON
    arrays["hand_flags"] = hand_flags.astype(str)
    arrays["hand_confidence"] = np.where(hand_flags == "", 0.9, 0.1)
    object_flags = arrays["object_flags"].astype(object)
    object_flags[0, object_frame] = OBJECT_REASON
    arrays["object_flags"] = object_flags.astype(str)
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    get_storage().put_bytes(key, buf.getvalue())
    return arrays


def _check_dexycb_flags(root: Path, arrays: dict[str, np.ndarray], ycb_ids: list[int],
                        hand_frame: int, object_frame: int) -> None:
    seq_dir = next(root.glob(dexycb.META_GLOB)).parent
    meta = yaml.safe_load((seq_dir / dexycb.META_FILE).read_text())
    flags = meta[dexycb_flags.META_LABEL_FLAGS]
    assert {int(f): r for f, r in flags["hand"].items()} == {hand_frame: HAND_REASON}
    assert {int(f): {int(o): r for o, r in v.items()} for f, v in flags["pose_y"].items()} == {
        object_frame: {0: OBJECT_REASON}}
    provenance = meta[dexycb_flags.META_LABEL_PROVENANCE]
    assert len(provenance["hand"]["views_decided"]) == len(arrays["labelled"])
    assert max(provenance["hand"]["views_decided"]) == len(provenance["hand"]["views"]) == 3
    pose = np.load(seq_dir / dexycb.POSE_FILE)
    assert (pose["pose_m"][hand_frame] == 0).all() and pose["pose_m_valid"][hand_frame, 0] == 0
    assert pose["pose_y_valid"][object_frame, 0] == 0 and pose["pose_y_valid"].sum() == (
        pose["pose_y_valid"].size - 1)
    for serial in meta[dexycb.META_SERIALS]:
        w2c = invert_pose(np.asarray(yaml.safe_load(
            (root / dexycb.extrinsics_file(meta[dexycb.META_EXTRINSICS])).read_text()
        )[dexycb.EXTRINSICS][serial]).reshape(3, 4))
        hand = np.load(seq_dir / serial / dexycb.labels_file(hand_frame))
        assert (hand["joint_3d"] == -1).all() and (hand["joint_2d"] == -1).all()
        assert (hand["pose_m"] == 0).all()
        assert (hand["seg"] == dexycb.HAND_SEG_VALUE).any()  # the mesh stays in seg
        lab = np.load(seq_dir / serial / dexycb.labels_file(object_frame))
        # The flagged row is the solved pose (not -1), the flag beside it.
        solved = np.concatenate([w2c[:, :3] @ arrays["object_poses"][0, object_frame][:, :3],
                                 (w2c[:, :3] @ arrays["object_poses"][0, object_frame][:, 3]
                                  + w2c[:, 3])[:, None]], axis=1)
        np.testing.assert_allclose(lab["pose_y"][0], solved, atol=2e-6)
        assert lab["pose_y_valid"].tolist() == [0, 1]
        assert (lab["seg"] == ycb_ids[0]).any()


def test_flagged_values_stay_beside_their_flags_in_every_format(
    client: TestClient, admin_headers: dict, approved: int, tmp_path: Path  # noqa: F811
) -> None:
    _solve(client, admin_headers, approved, {"optimiser": "default"})
    arrays = _flag_stored_result(approved, hand_frame=2, object_frame=3)
    with session_scope() as s:
        ycb_ids = [o.ycb_id for o in s.get_one(Sequence, approved).objects]
    state = _export(client, admin_headers, {"format": "dexycb", "sequences": [approved]})
    root = tmp_path / "dexycb"
    _download(client, admin_headers, state).extractall(root)
    _check_dexycb_flags(root, arrays, ycb_ids, 2, 3)

    state = _export(client, admin_headers, {"format": "coco", "sequences": [approved],
                                            "options": {"labels": "3d"}})
    document = json.loads(_download(client, admin_headers, state).read("annotations.json"))
    frame_of = {i["id"]: i["frame"] for i in document["images"]}
    flagged = [a for a in document["annotations"]
               if a["category_id"] == ycb_ids[0] and frame_of[a["image_id"]] == 3]
    assert flagged and all(a["iscrowd"] == 1 and a["pose_flag"] == OBJECT_REASON
                           and a["pose_valid"] is False for a in flagged)
    hands = [a for a in document["annotations"] if a["category_id"] == 255]
    assert {frame_of[a["image_id"]] for a in hands if a["iscrowd"]} == {2}
    assert all(a["hand_flag"] == (HAND_REASON if frame_of[a["image_id"]] == 2 else None)
               and "views_decided" in a["provenance"] for a in hands)

    state = _export(client, admin_headers, {"format": "bop", "sequences": [approved]})
    archive = _download(client, admin_headers, state)
    targets = json.loads(archive.read("test_targets_bop19.json"))
    for scene in json.loads(archive.read("scenes.json")):
        gt = json.loads(archive.read(f"test/{scene}/scene_gt.json"))["3"]
        info = json.loads(archive.read(f"test/{scene}/scene_gt_info.json"))["3"]
        [note] = [i["dexlabel"] for g, i in zip(gt, info, strict=True)
                  if g["obj_id"] == ycb_ids[0]]
        assert note["pose_valid"] is False and note["pose_flag"] == OBJECT_REASON
        assert not [t for t in targets if (t["scene_id"], t["im_id"], t["obj_id"]) == (
            int(scene), 3, ycb_ids[0])]
    assert any(t["obj_id"] == ycb_ids[0] and t["im_id"] != 3 for t in targets)

    actions = _give_edit_counts(approved)
    state = _export(client, admin_headers, {"format": "json", "sequences": [approved]})
    archive = _download(client, admin_headers, state)
    document = json.loads(archive.read(archive.namelist()[0]))
    jsonschema.validate(document, jsonfmt.schema())
    frames = document["solve"]["frames"]
    assert [f["hand_flag"] for f in frames].count(HAND_REASON) == 1 and frames[2]["hand_flag"]
    assert frames[3]["objects"][0]["flag"] == OBJECT_REASON and frames[3]["objects"][0]["pose"]
    _check_decisions(document["solve"]["provenance"], len(frames), actions)


def _give_edit_counts(sequence_id: int) -> dict[str, int]:
    """Each approved assignment's edit actions (as the page counts them): 7 per keyframe in the
    first view, 3 elsewhere; the total per target key."""
    out: dict[str, int] = {}
    with session_scope() as s:
        for a in s.scalars(select(Assignment).join(Task, Task.id == Assignment.task_id)
                           .where(Task.sequence_id == sequence_id,
                                  Assignment.status == "approved")):
            keyframes = sum(len(t.keyframes) for t in a.tracks)
            a.edit_count = keyframes * (7 if a.task.camera.view_index == 0 else 3)
            out[a.task.target_key] = out.get(a.task.target_key, 0) + a.edit_count
    return out


def _check_decisions(provenance: dict, frames: int, actions: dict[str, int]) -> None:
    """Per frame: the views that decided it (those whose state is keyframed or tracked) and the
    accepted work's actions shared out over its keyframes, adding up to that work's actions."""
    targets = [("hand:0", provenance["hand"])] + [
        (f"object:{i}", p) for i, p in enumerate(provenance["objects"])]
    for key, target in targets:
        assert len(target["actions"]) == len(target["deciding_views"]) == frames
        for f in range(frames):
            decided = sorted(s for s, states in target["views"].items()
                             if states[f] in ("keyframed", "tracked"))
            assert sorted(target["deciding_views"][f]) == decided
            assert len(decided) == target["views_decided"][f]
        assert sum(target["actions"]) == pytest.approx(actions[key], abs=0.01 * frames)
        # Every labelled view keyed its first frame: that frame took some of the actions.
        assert target["actions"][0] > 0


def test_hand_trust_reads_results_without_hand_flags_as_trusted() -> None:
    arrays = {"labelled": np.array([True, True, False])}
    confidence, flags = hand_trust(arrays)
    assert confidence.tolist() == [1.0, 1.0, 1.0] and flags.tolist() == ["", "", ""]
    arrays.update(hand_confidence=np.array([0.9, 0.1, 0.0]),
                  hand_flags=np.array(["", "interpolated in every view", ""]))
    confidence, flags = hand_trust(arrays)
    assert confidence.tolist() == [0.9, 0.1, 0.0]
    assert flags.tolist() == ["", "interpolated in every view", ""]
    arrays["hand_flags"] = np.array(["", ""])  # another length: not this result's
    assert hand_trust(arrays)[1].tolist() == ["", "", ""]
