"""Keyframe provenance through the annotation API and the export formats: a save stores each
keyframe's source (the 5th element of a row, only when it is not "placed"), the page reads it
back, submit accepts it, and a row with an unknown source or of the wrong length is refused 422 by
name, storing nothing; the JSON export spells every source out and CVAT carries it as a point
attribute that reads back."""

from __future__ import annotations

import io
from pathlib import Path
from xml.etree import ElementTree as ET

import jsonschema
import pytest
from fastapi.testclient import TestClient

from backend.captures.flows import import_path
from worker.formats import jsonfmt
from worker.formats.cvat import CvatVideoWriter, hand_label
from worker.formats.cvat_read import CvatFormatError, read_cvat_video
from worker.tracks.keyframes import Keyframe

NUM_FRAMES = 6  # the small capture's clip


@pytest.fixture
def hand_token(client: TestClient, admin_headers: dict, small_capture: Path) -> str:
    """The token of a fresh assignment of the small capture's first hand task."""
    seq_id = import_path(small_capture)[0].sequence_id
    tasks = client.post(f"/api/sequences/{seq_id}/tasks", headers=admin_headers).json()
    hand = next(t for t in tasks if t["kind"] == "hand")
    assert hand["num_frames"] == NUM_FRAMES
    resp = client.post(f"/api/tasks/{hand['id']}/assignments", json={"worker_id": "W1"},
                       headers=admin_headers)
    assert resp.status_code == 200, resp.text
    return str(resp.json()["token"])


def _bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


def _stored(client: TestClient, token: str) -> dict:
    """The assignment as the page reads it."""
    resp = client.get("/api/annotate/task", headers=_bearer(token))
    assert resp.status_code == 200, resp.text
    return dict(resp.json()["assignment"])


def _mixed_tracks() -> list[dict]:
    """21 complete tracks; point 1 carries every source, the others are placed."""
    tracks = [{"point": p, "keyframes": [[0, 10.0 + p, 20.0, 1], [5, 30.0 + p, 40.0, 1]]}
              for p in range(21)]
    tracks[1]["keyframes"] = [
        [0, 11.0, 20.0, 1, "placed"],
        [1, 12.0, 21.0, 1, "tracked"],
        [2, 13.0, 22.0, 0, "edited"],
        [3, None, None, 0, "prefilled"],
        [5, 31.0, 40.0, 1],
    ]
    return tracks


def test_sources_are_stored_and_read_back_in_the_short_form(
    client: TestClient, hand_token: str
) -> None:
    body = {"version": 0, "tracks": _mixed_tracks()}
    saved = client.put("/api/annotate/tracks", json=body, headers=_bearer(hand_token))
    assert saved.status_code == 200, saved.text
    tracks = _stored(client, hand_token)["tracks"]["tracks"]
    by_point = {t["point"]: t["keyframes"] for t in tracks}
    assert by_point[1] == [
        [0, 11.0, 20.0, 1],  # "placed" is the default and is not written
        [1, 12.0, 21.0, 1, "tracked"],
        [2, 13.0, 22.0, 0, "edited"],
        [3, None, None, 0, "prefilled"],
        [5, 31.0, 40.0, 1],
    ]
    assert by_point[0] == [[0, 10.0, 20.0, 1], [5, 30.0, 40.0, 1]]


def test_a_save_with_sources_can_be_submitted(client: TestClient, hand_token: str) -> None:
    body = {"version": 0, "tracks": _mixed_tracks()}
    resp = client.post("/api/annotate/submit", json=body, headers=_bearer(hand_token))
    assert resp.status_code == 200, resp.text
    assignment = _stored(client, hand_token)
    assert assignment["status"] == "submitted"
    assert assignment["tracks"]["tracks"][1]["keyframes"][1] == [1, 12.0, 21.0, 1, "tracked"]


ALLOWED = "source must be one of placed, tracked, prefilled, edited, got"


@pytest.mark.parametrize(("row", "problem"), [
    ([3, 12.0, 21.0, 1, "guessed"], f"index_tip: keyframe 1 (frame 3): {ALLOWED} 'guessed'"),
    ([3, 12.0, 21.0, 1, "Tracked"], f"{ALLOWED} 'Tracked'"),
    ([3, 12.0, 21.0, 1, 2], f"{ALLOWED} 2"),
    ([3, 12.0, 21.0, 1, "tracked", 0], "index_tip: keyframe 1 (frame 3): expected"),
])
def test_an_unknown_source_or_a_six_element_row_is_refused_by_name(
    client: TestClient, hand_token: str, row: list, problem: str
) -> None:
    first = {"version": 0, "tracks": _mixed_tracks()}
    assert client.put("/api/annotate/tracks", json=first, headers=_bearer(hand_token)).is_success
    body = {"version": 1, "tracks": [{"point": 8, "keyframes": [[0, 1.0, 1.0, 1], row]}]}
    resp = client.put("/api/annotate/tracks", json=body, headers=_bearer(hand_token))
    assert resp.status_code == 422, resp.text
    assert problem in resp.json()["detail"]
    # Nothing of the refused save is stored.
    assignment = _stored(client, hand_token)
    assert assignment["version"] == 1
    assert assignment["tracks"]["tracks"][8]["keyframes"] == [[0, 18.0, 20.0, 1],
                                                              [5, 38.0, 40.0, 1]]


# ---- export formats --------------------------------------------------------------------------

SOURCED_ROWS = [[0, 11.0, 20.0, 1], [2, 13.0, 22.0, 0, "edited"], [3, None, None, 0, "prefilled"],
                [4, 15.0, 24.0, 1, "tracked"]]


def _json_document(rows: list[list]) -> dict:
    """A minimal one-view document holding one hand assignment whose point 0 has ``rows``."""
    camera = {"view": 0, "serial": "cam0", "width": 64, "height": 48,
              "K": [[50.0, 0, 32.0], [0, 50.0, 24.0], [0, 0, 1]], "distortion": [0.0] * 5,
              "T_cam_to_world": [[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 1.0, 0]]}
    work = {"assignment_id": 1, "external_id": "A1", "worker_id": "W1", "status": "submitted",
            "task_id": 1, "view": 0, "serial": "cam0", "target_key": "hand:0", "kind": "hand",
            "working_time_s": 1.0, "edit_count": 3, "submitted_at": None, "qc": None,
            "points": [{"index": 0, "name": "wrist", "keyframes": rows, "dense": []}]}
    sequence = {"id": 1, "subject": "s", "name": "n", "num_frames": NUM_FRAMES, "fps": 30.0,
                "master_serial": "cam0"}
    return jsonfmt.sequence_document(sequence, [camera], [], [], [work], None, "submitted")


def test_the_json_export_spells_out_every_keyframe_source() -> None:
    document = _json_document(SOURCED_ROWS)
    jsonschema.validate(document, jsonfmt.schema())
    assert document["version"] == 2
    assert document["work"][0]["points"][0]["keyframes"] == [
        [0, 11.0, 20.0, 1, "placed"], [2, 13.0, 22.0, 0, "edited"],
        [3, None, None, 0, "prefilled"], [4, 15.0, 24.0, 1, "tracked"]]
    document["work"][0]["points"][0]["keyframes"][0][4] = "guessed"
    with pytest.raises(jsonschema.ValidationError, match="'guessed' is not one of"):
        jsonschema.validate(document, jsonfmt.schema())


def _cvat(points: list[list]) -> bytes:
    out = io.BytesIO()
    with CvatVideoWriter(out, [hand_label()], num_frames=NUM_FRAMES, width=64,
                         height=48) as writer:
        writer.add_track("hand", points)
    return out.getvalue()


def test_cvat_carries_the_source_as_a_declared_point_attribute_and_reads_it_back() -> None:
    points: list[list] = [SOURCED_ROWS] + [[[0, 1.0 + p, 2.0, 1]] for p in range(1, 21)]
    data = _cvat(points)
    root = ET.fromstring(data)
    wrist_label = next(lb for lb in root.iter("label") if lb.findtext("name") == "wrist")
    declared = {a.findtext("name"): (a.findtext("mutable"), a.findtext("input_type"),
                                     (a.findtext("values") or "").split("\n"))
                for a in wrist_label.iter("attribute")}
    assert declared["keyframe_source"] == ("True", "select",
                                           ["placed", "tracked", "prefilled", "edited"])
    wrist = [p for p in root.iter("points") if p.get("label") == "wrist"]
    written = [(p.get("keyframe"), p.findtext("attribute[@name='keyframe_source']"))
               for p in wrist]
    # Frames 0, 2, 3, 4 are keyframes; no other point has a keyframe elsewhere.
    assert written == [("1", "placed"), ("1", "edited"), ("1", "prefilled"), ("1", "tracked")]
    [track] = read_cvat_video(io.BytesIO(data)).tracks
    assert track.keyframes[0] == (Keyframe(0, 11.0, 20.0, True), Keyframe(2, 13.0, 22.0, False,
                                  "edited"), Keyframe(3, None, None, False, "prefilled"),
                                  Keyframe(4, 15.0, 24.0, True, "tracked"))
    bad = data.replace(b'name="keyframe_source">tracked<', b'name="keyframe_source">guessed<')
    with pytest.raises(CvatFormatError, match="keyframe_source 'guessed' is not one of placed"):
        read_cvat_video(io.BytesIO(bad))
