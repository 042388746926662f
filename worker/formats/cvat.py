"""CVAT for video 1.1 XML: a streaming writer of skeleton tracks.

Pure: keyframes in, XML bytes out through a binary file object (and back). Nothing here reads
the database or storage.

One document is one CVAT task in interpolation mode: one camera view of one sequence, frames
0..F-1 (F = ``num_frames``) of ``width`` x ``height`` pixels. Its tracks are the targets
labelled in that view (one per target, or one per assignment when submitted work is exported).

Input
-----
``CvatVideoWriter(out, labels, num_frames=F, width=W, height=H, name="", task_id=0,
video=None, dumped=None)`` writes the header and ``<meta>`` at once, so it takes the label set
up front: a sequence of :class:`SkeletonLabel` (``name``; ``points``, the point names in task
order; ``edges``, 0-based index pairs). :func:`hand_label` gives the 21 DexYCB joints
(:data:`worker.hand.joints.JOINT_NAMES`) with their 20 bones; :func:`object_label` gives an
object target's two landmarks (``landmark_1``, ``landmark_2``) joined by one edge. Label names
are unique; an object label is named as the caller likes (for example ``"object 003"``).

``writer.add_track(label, points, source="manual") -> int`` writes one ``<track>`` at once and
returns its id (0, 1, ...). ``points`` holds one keyframe list per point of the label, in the
label's order; a keyframe is what :func:`worker.tracks.keyframes.parse_keyframe` accepts (a
:class:`worker.tracks.keyframes.Keyframe`, a dict {frame, x, y, visible} or
[frame, x, y, visible01]), with x, y in image pixels (x right, y down) and frames in 0..F-1;
keyframes are checked with :func:`worker.tracks.validate.validate_keyframes` and a ValueError
names the point and the problem.
``source`` is CVAT's: ``"manual"`` for crowd tracks, ``"auto"`` for computed ones (consensus).
``writer.close()`` ends the document (``with`` does it on success). Nothing is kept in memory
between tracks.

Output
------
``<annotations><version>1.1</version><meta><task>`` with id, name, size (F), mode
(interpolation), overlap, start_frame (0), stop_frame (F-1), one segment 0..F-1, the labels
and ``<original_size>`` (W, H), then ``<dumped>`` (and ``<source>``, the video's name). Each
skeleton label is written as CVAT writes one: a ``<label>`` of type skeleton whose ``<svg>``
holds an element node (``<circle data-type="element node" data-element-id data-node-id
data-label-name>``) per point and an edge (``<line data-type="edge" data-node-from
data-node-to>``) per bone, 1-based, followed by one points ``<label>`` per point with the
skeleton as ``<parent>`` and two mutable select attributes: ``position`` (placed, none,
unplaced), that tells a position from a placeholder, and ``keyframe_source`` (placed, tracked,
prefilled, edited; default placed), the keyframe's provenance
(:data:`worker.tracks.keyframes.SOURCES`; named so as not to be taken for CVAT's own track
``source``, manual or auto).

``<track id label source>`` holds ``<skeleton frame keyframe="1" outside="0" occluded="0"
z_order="0">`` shapes at every frame where one of its points has a keyframe, each listing every
point as ``<points label keyframe outside occluded points="x,y">`` (2 decimals, as CVAT
writes) with its ``position`` and ``keyframe_source`` attributes. Points without a keyframe at
that frame carry the value CVAT interpolates there, with keyframe="0" (and, as CVAT does for a
mutable attribute, the attributes of the keyframe before). An unplaced placeholder is "placed",
the attribute's default. Our model maps onto CVAT's as follows:

- A keyframe with a position: a CVAT keyframe, outside=0, occluded = not visible, position
  placed. CVAT interpolates single points linearly and copies ``occluded`` from the keyframe
  before, as :func:`worker.tracks.interpolate.dense_track` does; after the last keyframe both
  hold to the end of the clip, so no closing outside=1 shape is written (CVAT's own writer adds
  one only to a shape that ends before the last frame).
- An occluded keyframe without a position: a CVAT keyframe with outside=1, occluded=1,
  position none: the point is absent until its next keyframe, as it has no position in ours.
  Placement rule: the previous keyframe's position when that keyframe has one (CVAT
  interpolates toward an outside keyframe's position, so this holds the previous position up to
  this frame, as ours does), else the next position the point gets, else the mean of the
  target's other positioned points at that frame, else the image centre.
- Before a point's first keyframe it is unplaced. Every point gets a keyframe at the track's
  first skeleton frame so that every skeleton lists every point (CVAT drops points missing
  there); one not placed yet there is outside=1, position unplaced, placed by the same rule.
- A point with no position at any keyframe (occluded without position throughout, or never
  placed) would be outside in every frame, which CVAT mishandles (cvat-ai/cvat#8844: the point
  vanishes on export and the file no longer imports); its keyframes are then written with
  outside=0, occluded=1 at their placements, the ``position`` attribute saying none/unplaced.

The document reads back with :func:`worker.formats.cvat_read.read_cvat_video`.
"""

from __future__ import annotations

import bisect
import math
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import IO, Any, Literal
from xml.sax.saxutils import escape

import numpy as np

from worker.formats.writer import StreamWriter
from worker.hand.joints import JOINT_NAMES, JOINT_PARENTS
from worker.tracks.interpolate import dense_points
from worker.tracks.keyframes import SOURCES, Keyframe, KeyframeSource, as_keyframes
from worker.tracks.validate import validate_keyframes

VERSION = "1.1"
POSITION_ATTRIBUTE = "position"
PLACED, NO_POSITION, UNPLACED = "placed", "none", "unplaced"
POSITION_VALUES: tuple[str, ...] = (PLACED, NO_POSITION, UNPLACED)
OBJECT_LANDMARKS: tuple[str, ...] = ("landmark_1", "landmark_2")
SOURCE_ATTRIBUTE = "keyframe_source"

# Characters XML 1.0 cannot carry, even escaped.
_NOT_XML = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\ud800-\udfff\ufffe\uffff]")
_ATTR_ESCAPES = {'"': "&quot;", "\n": "&#10;", "\r": "&#13;", "\t": "&#9;"}


def _text(value: str, what: str) -> str:
    if _NOT_XML.search(value):
        raise ValueError(f"{what} {value!r} has a character XML cannot hold")
    return value


def _q(value: str) -> str:
    return '"' + escape(value, _ATTR_ESCAPES) + '"'


@dataclass(frozen=True)
class SkeletonLabel:
    """A CVAT skeleton label: its name, its point names in task order, 0-based edges."""

    name: str
    points: tuple[str, ...]
    edges: tuple[tuple[int, int], ...] = ()

    def __post_init__(self) -> None:
        _text(self.name, "label name")
        if not self.name or not self.points:
            raise ValueError("a skeleton label needs a name and at least one point")
        if len(set(self.points)) != len(self.points):
            raise ValueError(f"label {self.name!r}: point names repeat: {self.points}")
        for point in self.points:
            _text(point, "point name")
        for a, b in self.edges:
            if not (0 <= a < len(self.points) and 0 <= b < len(self.points)) or a == b:
                raise ValueError(f"label {self.name!r}: edge ({a}, {b}) is not between 2 points")


def hand_label(name: str = "hand") -> SkeletonLabel:
    """The 21 DexYCB hand joints with their 20 bones (parent, child)."""
    edges = tuple((JOINT_PARENTS[j], j) for j in range(1, len(JOINT_NAMES)))
    return SkeletonLabel(name, JOINT_NAMES, edges)


def object_label(name: str, landmarks: Sequence[str] = OBJECT_LANDMARKS) -> SkeletonLabel:
    """An object target's landmarks as a skeleton, consecutive landmarks joined by an edge."""
    edges = tuple((i, i + 1) for i in range(len(landmarks) - 1))
    return SkeletonLabel(name, tuple(landmarks), edges)


def _layout(label: SkeletonLabel) -> list[tuple[float, float]]:
    """Node positions in CVAT's 100 x 100 skeleton canvas: a hand fans out its fingers."""
    if label.points == JOINT_NAMES:
        spots = [(50.0, 92.0)]
        for finger in range(5):
            angle = math.radians(-40.0 + 20.0 * finger)
            spots += [(50.0 + r * math.sin(angle), 92.0 - r * math.cos(angle))
                      for r in (22.0, 38.0, 52.0, 66.0)]
        return spots
    n = len(label.points)
    return [(100.0 * (i + 1) / (n + 1), 50.0) for i in range(n)]


def _svg(label: SkeletonLabel) -> str:
    spots = _layout(label)
    parts = [
        f'<line x1="{spots[a][0]:.2f}" y1="{spots[a][1]:.2f}" x2="{spots[b][0]:.2f}" '
        f'y2="{spots[b][1]:.2f}" stroke="black" data-type="edge" data-node-from="{a + 1}" '
        f'stroke-width="0.5" data-node-to="{b + 1}"></line>'
        for a, b in label.edges
    ]
    parts += [
        f'<circle r="1.5" stroke="black" fill="#b3b3b3" cx="{x:.2f}" cy="{y:.2f}" '
        f'stroke-width="0.1" data-type="element node" data-element-id="{i + 1}" '
        f'data-node-id="{i + 1}" data-label-name={_q(point)}></circle>'
        for i, (point, (x, y)) in enumerate(zip(label.points, spots, strict=True))
    ]
    return "".join(parts)


def _select_attribute(name: str, values: Sequence[str]) -> str:
    """A mutable select attribute of a label, its first value the default."""
    return (f"<attribute><name>{name}</name><mutable>True</mutable>"
            f"<input_type>select</input_type><default_value>{values[0]}</default_value>"
            f"<values>{escape(chr(10).join(values))}</values></attribute>")


def _labels_xml(labels: Sequence[SkeletonLabel]) -> str:
    position = (f"<attributes>{_select_attribute(POSITION_ATTRIBUTE, POSITION_VALUES)}"
                f"{_select_attribute(SOURCE_ATTRIBUTE, SOURCES)}</attributes>")
    out = []
    for label in labels:
        out.append(f"<label><name>{escape(label.name)}</name><type>skeleton</type>"
                   f"<attributes></attributes><svg>{escape(_svg(label))}</svg></label>")
        out += [f"<label><name>{escape(point)}</name><type>points</type>{position}"
                f"<parent>{escape(label.name)}</parent></label>" for point in label.points]
    return "".join(out)


@dataclass(frozen=True)
class CvatElement:
    """One point's CVAT keyframe (an element shape of a skeleton): position (px), flags and the
    ``position`` and ``keyframe_source`` attributes; shared with the reader (cvat_read)."""

    frame: int
    x: float
    y: float
    outside: bool
    occluded: bool
    position: str
    source: KeyframeSource = "placed"


def _placement(kfs: Sequence[Keyframe], index: int, fallback: tuple[float, float]
               ) -> tuple[float, float]:
    """Where a keyframe without position (or the unplaced start, index -1) is written."""
    before = kfs[index - 1] if index > 0 else None
    if before is not None and before.x is not None and before.y is not None:
        return before.x, before.y
    for k in kfs[index + 1:]:
        if k.x is not None and k.y is not None:
            return k.x, k.y
    return fallback


def _point_elements(kfs: Sequence[Keyframe], first_frame: int,
                    fallback: np.ndarray) -> list[CvatElement]:
    """One point's CVAT keyframes (see the module docstring); fallback: (F, 2) placements."""
    elements = []
    if not kfs or kfs[0].frame > first_frame:
        x, y = _placement(kfs, -1, tuple(fallback[first_frame]))
        elements.append(CvatElement(first_frame, x, y, True, False, UNPLACED))
    for i, k in enumerate(kfs):
        if k.x is not None and k.y is not None:
            elements.append(CvatElement(k.frame, k.x, k.y, False, not k.visible, PLACED, k.source))
        else:
            x, y = _placement(kfs, i, tuple(fallback[k.frame]))
            elements.append(CvatElement(k.frame, x, y, True, True, NO_POSITION, k.source))
    if all(e.outside for e in elements):  # cvat-ai/cvat#8844
        elements = [CvatElement(e.frame, e.x, e.y, False, True, e.position, e.source)
                    for e in elements]
    return elements


def _cvat_value(elements: Sequence[CvatElement], frames: Sequence[int], frame: int) -> CvatElement:
    """The value CVAT interpolates for a point at a frame that is not one of its keyframes."""
    i = bisect.bisect_right(frames, frame) - 1
    k0 = elements[i]
    x, y = k0.x, k0.y
    if not k0.outside and i + 1 < len(elements):
        k1 = elements[i + 1]
        t = (frame - k0.frame) / (k1.frame - k0.frame)
        x, y = x + (k1.x - x) * t, y + (k1.y - y) * t
    return CvatElement(frame, x, y, k0.outside, k0.occluded, k0.position, k0.source)


def _points_xml(name: str, e: CvatElement, keyframe: bool) -> str:
    return (f"<points label={_q(name)} keyframe=\"{int(keyframe)}\" outside=\"{int(e.outside)}\" "
            f"occluded=\"{int(e.occluded)}\" points=\"{e.x:.2f},{e.y:.2f}\">"
            f'<attribute name="{POSITION_ATTRIBUTE}">{e.position}</attribute>'
            f'<attribute name="{SOURCE_ATTRIBUTE}">{e.source}</attribute></points>')


class CvatVideoWriter(StreamWriter):
    """Writes one CVAT for video 1.1 document track by track (see the module docstring)."""

    def __init__(self, out: IO[bytes], labels: Sequence[SkeletonLabel], *, num_frames: int,
                 width: int, height: int, name: str = "", task_id: int = 0,
                 video: str | None = None, dumped: datetime | None = None) -> None:
        if num_frames < 1 or width < 1 or height < 1:
            raise ValueError(f"need num_frames, width, height >= 1, got {num_frames}, "
                             f"{width}, {height}")
        names = [label.name for label in labels]
        if len(set(names)) != len(names):
            raise ValueError(f"label names repeat: {names}")
        self._out, self._labels = out, {label.name: label for label in labels}
        self._num_frames, self._width, self._height = num_frames, width, height
        self._next_id, self._closed = 0, False
        stop = num_frames - 1
        stamp = (dumped or datetime.now(UTC)).isoformat()
        self._write(
            f'<?xml version="1.0" encoding="utf-8"?>\n<annotations>\n<version>{VERSION}</version>\n'
            f"<meta><task><id>{task_id}</id><name>{escape(_text(name, 'name'))}</name>"
            f"<size>{num_frames}</size><mode>interpolation</mode><overlap>0</overlap>"
            f"<bugtracker></bugtracker><created>{stamp}</created><updated>{stamp}</updated>"
            f"<subset>default</subset><start_frame>0</start_frame><stop_frame>{stop}</stop_frame>"
            f"<frame_filter></frame_filter><segments><segment><id>0</id><start>0</start>"
            f"<stop>{stop}</stop><url></url></segment></segments>"
            f"<labels>{_labels_xml(labels)}</labels>"
            f"<original_size><width>{width}</width><height>{height}</height></original_size>"
            f"</task><dumped>{stamp}</dumped>"
            + (f"<source>{escape(_text(video, 'video'))}</source>" if video else "")
            + "</meta>\n"
        )

    def _write(self, text: str) -> None:
        self._out.write(text.encode("utf-8"))

    def add_track(self, label: str, points: Sequence[Iterable[Any]], *,
                  source: Literal["manual", "auto"] = "manual") -> int:
        """Writes one track: one keyframe list per point of ``label``, in its order."""
        if self._closed:
            raise ValueError("the document is closed")
        if label not in self._labels:
            raise ValueError(f"unknown label {label!r}; the labels are {list(self._labels)}")
        spec = self._labels[label]
        if len(points) != len(spec.points):
            raise ValueError(f"label {label!r} has {len(spec.points)} points, got {len(points)}")
        tracks = []
        for name, raw in zip(spec.points, points, strict=True):
            raw = list(raw)
            problems = validate_keyframes(raw, self._num_frames, self._width, self._height)
            if problems:
                raise ValueError(f"{label} {name}: {'; '.join(problems)}")
            tracks.append(as_keyframes(raw))
        elements = self._elements(tracks)
        track_id, self._next_id = self._next_id, self._next_id + 1
        lines = [f"<track id=\"{track_id}\" label={_q(label)} source=\"{source}\">"]
        frame_lists = [[e.frame for e in point] for point in elements]
        for frame in sorted({f for frames in frame_lists for f in frames}):
            lines.append(f'<skeleton frame="{frame}" keyframe="1" outside="0" occluded="0" '
                         'z_order="0">')
            for name, point, frames in zip(spec.points, elements, frame_lists, strict=True):
                i = bisect.bisect_left(frames, frame)
                if i < len(frames) and frames[i] == frame:
                    lines.append(_points_xml(name, point[i], True))
                else:
                    lines.append(_points_xml(name, _cvat_value(point, frames, frame), False))
            lines.append("</skeleton>")
        lines.append("</track>\n")
        self._write("\n".join(lines))
        return track_id

    def _elements(self, tracks: list[list[Keyframe]]) -> list[list[CvatElement]]:
        xy, _ = dense_points(list(enumerate(tracks)), self._num_frames, len(tracks))
        placed = ~np.isnan(xy).any(axis=2)  # (F, P)
        centre = np.array([self._width / 2.0, self._height / 2.0])
        counts = placed.sum(axis=1, keepdims=True)
        sums = np.where(placed[..., None], xy, 0.0).sum(axis=1)
        fallback = np.where(counts > 0, sums / np.maximum(counts, 1), centre)  # (F, 2)
        starts = [kfs[0].frame for kfs in tracks if kfs]
        first_frame = min(starts) if starts else 0
        return [_point_elements(kfs, first_frame, fallback) for kfs in tracks]

    def close(self) -> None:
        """Ends the document (a second call does nothing)."""
        if not self._closed:
            self._write("</annotations>\n")
            self._closed = True
