"""dexlabel's own JSON export: one document per sequence, described by ``jsonfmt.schema.json``.

Pure: plain values in, one JSON document (bytes) out. A document holds the sequence (cameras
with K, distortion and camera-to-world extrinsics; objects; hands), the labelled work (one entry
per assignment: the keyframes of every point with their source, the dense per-frame track, who
did it, how long it took and its QC outcome) and the current solve (per frame: labelled flag and
reason, MANO pose_m, the 21 joints, object poses, reprojection error per view and joint, depth
RMS) with its consensus (the solved joints reprojected into each view, with that view's
distortion).

Units: pixels (x right, y down, as OpenCV projects), metres, world = the capture's master frame.
JSON has no NaN: a missing number is null.

A keyframe is written [frame, x, y, visible01, source] with its source always spelled out
("placed", "tracked", "prefilled" or "edited"; see worker.tracks), whereas stored rows leave out
"placed". Format version 2 added the source; version 1 wrote [frame, x, y, visible01].
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from importlib import resources
from typing import Any

import numpy as np

from worker.tracks.keyframes import parse_keyframe

FORMAT_NAME = "dexlabel-json"
FORMAT_VERSION = 2
SCHEMA_FILE = "jsonfmt.schema.json"


def schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) every document validates against."""
    text = resources.files("worker.formats").joinpath(SCHEMA_FILE).read_text(encoding="utf-8")
    loaded: dict[str, Any] = json.loads(text)
    return loaded


def finite(values: Any) -> Any:
    """Arrays and numbers as nested lists with None where a number is not finite."""
    if isinstance(values, np.ndarray):
        values = values.tolist()
    if isinstance(values, (list, tuple)):
        return [finite(v) for v in values]
    if isinstance(values, float) and not math.isfinite(values):
        return None
    if isinstance(values, (np.floating, np.integer)):
        return finite(values.item())
    return values


def keyframe_row(raw: Any) -> list[Any]:
    """A keyframe (a stored row, a dict or a :class:`worker.tracks.keyframes.Keyframe`) as exported:
    [frame, x px, y px, visible01, source], the source always written."""
    kf = parse_keyframe(raw)
    return [kf.frame, kf.x, kf.y, 1 if kf.visible else 0, kf.source]


def _work_entry(work: Mapping[str, Any]) -> dict[str, Any]:
    """One work entry with its points' keyframes in the exported form."""
    entry = dict(work)
    if "points" in entry:
        entry["points"] = [{**point, "keyframes": [keyframe_row(k) for k in point["keyframes"]]}
                           for point in entry["points"]]
    return entry


def dense_track(xy: np.ndarray, visible: np.ndarray) -> list[list[list[Any]]]:
    """(F, P, 2) px and (F, P) bool as per frame, per point [x, y, visible] (x, y None where the
    point has no position)."""
    xy = np.asarray(xy, dtype=np.float64)
    visible = np.asarray(visible, dtype=bool)
    if xy.ndim != 3 or xy.shape[2] != 2 or visible.shape != xy.shape[:2]:
        raise ValueError(f"xy must be (F, P, 2) and visible (F, P), got {xy.shape}, "
                         f"{visible.shape}")
    out = []
    for f in range(xy.shape[0]):
        row = []
        for p in range(xy.shape[1]):
            x, y = xy[f, p]
            placed = math.isfinite(x) and math.isfinite(y)
            row.append([float(x) if placed else None, float(y) if placed else None,
                        bool(visible[f, p])])
        out.append(row)
    return out


def sequence_document(sequence: Mapping[str, Any], cameras: Sequence[Mapping[str, Any]],
                      objects: Sequence[Mapping[str, Any]], hands: Sequence[Mapping[str, Any]],
                      work: Sequence[Mapping[str, Any]], solve: Mapping[str, Any] | None,
                      include: str) -> dict[str, Any]:
    """The document of one sequence (see the schema for every field)."""
    return finite({
        "format": FORMAT_NAME, "version": FORMAT_VERSION, "include": include,
        "sequence": dict(sequence), "cameras": [dict(c) for c in cameras],
        "objects": [dict(o) for o in objects], "hands": [dict(h) for h in hands],
        "work": [_work_entry(w) for w in work], "solve": None if solve is None else dict(solve),
    })


def document_bytes(document: Mapping[str, Any]) -> bytes:
    return json.dumps(document, separators=(",", ":"), allow_nan=False).encode("utf-8")
