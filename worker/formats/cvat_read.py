"""CVAT for video 1.1 XML read back: skeleton tracks as our keyframes and occlusion spans.

Pure: a binary file object (or a path) in, a :class:`CvatVideo` out. The document is the one
:mod:`worker.formats.cvat` writes (its docstring maps our keyframe model onto CVAT's), or one
authored in CVAT.

:func:`read_cvat_video` parses such a document (stdlib ElementTree: DOCTYPE and entity
declarations are refused, elements are released track by track) into a :class:`CvatVideo`
(name, num_frames, width, height, labels, tracks). Like CVAT's importer it takes only element
shapes with keyframe="1". Each :class:`CvatTrack` gives per point its keyframes and occlusion
spans (inclusive [start, end] frames where the point is placed but occluded, from CVAT's
semantics: a keyframe's flags hold until the next) with their sources. Where the ``position``
attribute is absent (a file authored in CVAT), an outside keyframe before the point's first
positioned one is taken as unplaced and a later one as an occluded keyframe without position;
where ``keyframe_source`` is absent the keyframe is "placed". Malformed input
raises :class:`CvatFormatError` naming the problem and where it is.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import IO
from xml.etree import ElementTree as ET

import numpy as np

from worker.formats.cvat import (
    NO_POSITION,
    PLACED,
    POSITION_ATTRIBUTE,
    POSITION_VALUES,
    SOURCE_ATTRIBUTE,
    UNPLACED,
    VERSION,
    CvatElement,
    SkeletonLabel,
)
from worker.tracks.keyframes import SOURCES, Keyframe, KeyframeSource
from worker.tracks.spans import frame_spans


class CvatFormatError(ValueError):
    """A document that is not CVAT for video 1.1 as this module reads it."""


@dataclass(frozen=True)
class CvatTrack:
    """A skeleton track read back: per point (label order) its keyframes and occlusion spans."""

    id: int
    label: str
    source: str
    keyframes: tuple[tuple[Keyframe, ...], ...]
    occluded: tuple[tuple[tuple[int, int], ...], ...]


@dataclass(frozen=True)
class CvatVideo:
    """A CVAT for video document: the task's frames, size (px), labels and tracks."""

    name: str
    num_frames: int
    width: int
    height: int
    labels: tuple[SkeletonLabel, ...]
    tracks: tuple[CvatTrack, ...]


# What a document's meta says: task name, num_frames, width, height, skeleton labels by name.
_Meta = tuple[str, int, int, int, dict[str, SkeletonLabel]]


def _required(el: ET.Element, name: str, where: str) -> str:
    value = el.get(name)
    if value is None:
        raise CvatFormatError(f"{where}: <{el.tag}> has no {name} attribute")
    return value


def _int(el: ET.Element, name: str, where: str) -> int:
    value = _required(el, name, where)
    try:
        return int(value)
    except ValueError:
        raise CvatFormatError(f"{where}: {name}={value!r} is not an integer") from None


def _flag(el: ET.Element, name: str, where: str) -> bool:
    value = _required(el, name, where)
    if value not in ("0", "1"):
        raise CvatFormatError(f"{where}: {name}={value!r} is not 0 or 1")
    return value == "1"


def _xy(el: ET.Element, where: str) -> tuple[float, float]:
    value = _required(el, "points", where)
    try:
        x, y = (float(v) for v in value.split(","))
    except ValueError:
        raise CvatFormatError(f"{where}: points={value!r} is not one 'x,y' pair") from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise CvatFormatError(f"{where}: points={value!r} is not finite")
    return x, y


def _meta_int(task: ET.Element, path: str) -> int:
    text = task.findtext(path)
    if text is None:
        raise CvatFormatError(f"meta: <task> has no <{path}>")
    try:
        return int(text.strip())
    except ValueError:
        raise CvatFormatError(f"meta: <{path}> {text!r} is not an integer") from None


def _skeleton_from_meta(label: ET.Element, children: list[str]) -> SkeletonLabel:
    name = label.findtext("name") or ""
    edges: list[tuple[int, int]] = []
    svg = label.findtext("svg")
    if svg:
        try:
            nodes = ET.fromstring(f"<svg>{svg}</svg>")
        except ET.ParseError as exc:
            raise CvatFormatError(f"meta: label {name!r}: <svg> does not parse: {exc}") from None
        by_node = {n.get("data-node-id"): n.get("data-label-name") for n in nodes
                   if n.get("data-type") == "element node"}
        for line in nodes:
            if line.get("data-type") == "edge":
                ends = (by_node.get(line.get("data-node-from")),
                        by_node.get(line.get("data-node-to")))
                if not all(end in children for end in ends):
                    raise CvatFormatError(f"meta: label {name!r}: an edge refers to no point")
                edges.append((children.index(str(ends[0])), children.index(str(ends[1]))))
    try:
        return SkeletonLabel(name, tuple(children), tuple(edges))
    except ValueError as exc:
        raise CvatFormatError(f"meta: {exc}") from None


def _parse_meta(meta: ET.Element) -> _Meta:
    task = meta.find("task")
    if task is None:
        task = meta.find("job")
    if task is None:
        raise CvatFormatError("meta: no <task>")
    if (task.findtext("mode") or "interpolation").strip() != "interpolation":
        raise CvatFormatError("meta: mode is not interpolation (this is CVAT for images)")
    num_frames = _meta_int(task, "size")
    width, height = _meta_int(task, "original_size/width"), _meta_int(task, "original_size/height")
    skeletons: list[ET.Element] = []
    children: dict[str, list[str]] = {}
    for label in task.iterfind("labels/label"):
        name, parent = label.findtext("name"), label.findtext("parent")
        if not name:
            raise CvatFormatError("meta: a <label> has no <name>")
        if (label.findtext("type") or "").strip() == "skeleton":
            skeletons.append(label)
            children.setdefault(name, [])
        elif parent:
            children.setdefault(parent, []).append(name)
    labels = {s.findtext("name") or "": _skeleton_from_meta(s, children[s.findtext("name") or ""])
              for s in skeletons}
    return task.findtext("name") or "", num_frames, width, height, labels


def _select_value(points: ET.Element, name: str, values: Sequence[str],
                  where: str) -> str | None:
    """The value of the select attribute ``name`` of a point shape, None when absent."""
    for attribute in points.iterfind("attribute"):
        if attribute.get("name") == name:
            value = (attribute.text or "").strip()
            if value not in values:
                raise CvatFormatError(f"{where}: {name} {value!r} is not one of "
                                      f"{', '.join(values)}")
            return value
    return None


def _source_of(value: str) -> KeyframeSource:
    """A value _select_value checked against SOURCES, typed as a source."""
    return next(s for s in SOURCES if s == value)


def _to_keyframes(elements: list[CvatElement], num_frames: int
                  ) -> tuple[tuple[Keyframe, ...], tuple[tuple[int, int], ...]]:
    """One point's CVAT keyframes (sorted) as our keyframes and occlusion spans."""
    keyframes: list[Keyframe] = []
    occluded = np.zeros(num_frames, dtype=bool)
    seen_position = False
    for i, e in enumerate(elements):
        position = e.position
        if not position:  # no attribute: a file authored in CVAT
            position = (PLACED if not e.outside else NO_POSITION if seen_position else UNPLACED)
        seen_position |= position == PLACED
        end = elements[i + 1].frame if i + 1 < len(elements) else num_frames
        if position == PLACED:
            keyframes.append(Keyframe(e.frame, e.x, e.y, not e.occluded, e.source))
            occluded[e.frame:end] = e.occluded
        elif position == NO_POSITION:
            keyframes.append(Keyframe(e.frame, None, None, False, e.source))
            occluded[e.frame:end] = True
    spans = tuple((int(a), int(b)) for a, b in frame_spans(occluded))
    return tuple(keyframes), spans


def _parse_track(track: ET.Element, labels: dict[str, SkeletonLabel],
                 num_frames: int) -> CvatTrack:
    track_id = _int(track, "id", "track")
    where = f"track {track_id}"
    label = _required(track, "label", where)
    if label not in labels:
        raise CvatFormatError(f"{where}: label {label!r} is not a skeleton label of the meta")
    spec = labels[label]
    per_point: dict[str, dict[int, CvatElement]] = {name: {} for name in spec.points}
    for skeleton in track:
        if skeleton.tag != "skeleton":
            raise CvatFormatError(f"{where}: <{skeleton.tag}> shapes are not read; "
                                  "expected <skeleton>")
        frame = _int(skeleton, "frame", where)
        at = f"{where} frame {frame}"
        _flag(skeleton, "keyframe", at)
        if not 0 <= frame < num_frames:
            raise CvatFormatError(f"{at}: frame out of range 0-{num_frames - 1}")
        for points in skeleton:
            if points.tag == "attribute":
                continue
            name = _required(points, "label", at) if points.tag == "points" else ""
            if name not in per_point:
                raise CvatFormatError(f"{at}: <{points.tag} label={name!r}> is not a point "
                                      f"of {label!r}")
            here = f"{at} point {name!r}"
            keyframe, outside = _flag(points, "keyframe", here), _flag(points, "outside", here)
            occluded, (x, y) = _flag(points, "occluded", here), _xy(points, here)
            position = _select_value(points, POSITION_ATTRIBUTE, POSITION_VALUES, here) or ""
            source = _select_value(points, SOURCE_ATTRIBUTE, SOURCES, here) or "placed"
            if keyframe:  # CVAT's importer takes keyframe element shapes only
                if frame in per_point[name]:
                    raise CvatFormatError(f"{here}: a second keyframe at the same frame")
                per_point[name][frame] = CvatElement(frame, x, y, outside, occluded, position,
                                                  _source_of(source))
    read = [_to_keyframes([shapes[f] for f in sorted(shapes)], num_frames)
            for shapes in per_point.values()]
    return CvatTrack(track_id, label, track.get("source", "manual"),
                     tuple(k for k, _ in read), tuple(s for _, s in read))


@dataclass
class _Document:
    """What has been read of a document so far: the children of <annotations> taken in turn."""

    version: str | None = None
    meta: _Meta | None = None
    tracks: list[CvatTrack] = field(default_factory=list)

    def take(self, el: ET.Element) -> None:
        """Reads one child of <annotations> once its end tag has been parsed."""
        if el.tag == "version":
            self.version = (el.text or "").strip()
        elif el.tag == "meta":
            self.meta = _parse_meta(el)
        elif el.tag == "track":
            if self.meta is None:
                raise CvatFormatError("a <track> comes before <meta>")
            self.tracks.append(_parse_track(el, self.meta[4], self.meta[1]))
        elif el.tag in ("image", "tag"):
            raise CvatFormatError(f"<{el.tag}> found: this is CVAT for images, not video")

    def video(self) -> CvatVideo:
        """The document read, once it has been parsed to its end."""
        if self.version != VERSION:
            raise CvatFormatError(f"version is {self.version!r}, expected {VERSION!r}")
        if self.meta is None:
            raise CvatFormatError("no <meta>")
        name, num_frames, width, height, labels = self.meta
        return CvatVideo(name, num_frames, width, height, tuple(labels.values()),
                         tuple(self.tracks))


def _stream(source: IO[bytes], document: _Document) -> ET.Element | None:
    """Parses ``source`` chunk by chunk into ``document``, releasing each child of the root once
    read; returns the root (None for an empty document). Raises ET.ParseError on bad XML."""
    parser: ET.XMLPullParser[ET.Element] = ET.XMLPullParser(events=("start", "end"))
    root: ET.Element | None = None
    prolog = b""
    depth = 0
    while chunk := source.read(1 << 16):
        if root is None:
            prolog += chunk
            if b"<!DOCTYPE" in prolog or b"<!ENTITY" in prolog:
                raise CvatFormatError("DOCTYPE and entity declarations are refused")
        parser.feed(chunk)
        for item in parser.read_events():
            event, el = item[0], item[-1]
            if not isinstance(el, ET.Element):  # only start and end events are asked for
                continue
            if event == "start":
                depth += 1
                if root is None:
                    if el.tag != "annotations":
                        raise CvatFormatError(f"the root is <{el.tag}>, not <annotations>")
                    root = el
                continue
            depth -= 1
            if depth != 1 or root is None:
                continue
            document.take(el)
            root.remove(el)  # release what has been read
    parser.close()
    return root


def read_cvat_video(source: IO[bytes] | str | os.PathLike[str]) -> CvatVideo:
    """Reads a CVAT for video 1.1 document of skeleton tracks (see the module docstring).

    Raises:
        CvatFormatError: naming the problem (not XML, not CVAT for video 1.1, a missing or bad
            attribute with its track, frame and point).
    """
    if isinstance(source, (str, os.PathLike)):
        with open(source, "rb") as stream:
            return read_cvat_video(stream)
    document = _Document()
    try:
        root = _stream(source, document)
    except ET.ParseError as exc:
        raise CvatFormatError(f"not well-formed XML: {exc}") from None
    if root is None:
        raise CvatFormatError("empty document")
    return document.video()
