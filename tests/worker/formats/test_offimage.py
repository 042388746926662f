"""A joint that leaves the image is exported outside: the stretch becomes a keyframe without a
position (CVAT outside=1), the values around it unchanged."""

from __future__ import annotations

import io

import numpy as np

from worker.formats.cvat import CvatVideoWriter, object_label
from worker.formats.cvat_read import read_cvat_video
from worker.formats.offimage import mark_outside
from worker.tracks.interpolate import dense_track

FRAMES = 10
# Worker keyframes (px): the point runs to the left border at frame 4 (stored clamped there,
# occluded) and comes back; the solve says it is outside the image over frames 3-5.
TRACK = [[0, 40.0, 50.0, 1], [4, 0.0, 50.0, 0], [8, 40.0, 60.0, 1, "tracked"]]
OUTSIDE = np.zeros(FRAMES, dtype=bool)
OUTSIDE[3:6] = True


def test_the_outside_stretch_has_no_position_and_the_rest_is_unchanged() -> None:
    marked = mark_outside(TRACK, OUTSIDE)
    before, after = dense_track(TRACK, FRAMES), dense_track(marked, FRAMES)
    assert not np.isfinite(after.xy[3:6]).any()
    np.testing.assert_allclose(after.xy[~OUTSIDE], before.xy[~OUTSIDE])
    assert (after.visible[~OUTSIDE] == before.visible[~OUTSIDE]).all()
    frames = [k.frame for k in marked]
    assert frames == [0, 2, 3, 6, 8]
    # The keyframe after the stretch carries the value (and source) the track had there.
    assert (marked[3].x, marked[3].y, marked[3].source) == (20.0, 55.0, "placed")


def test_a_track_always_inside_is_left_as_it_is() -> None:
    marked = mark_outside(TRACK, np.zeros(FRAMES, dtype=bool))
    assert [k.row() for k in marked] == [list(r) for r in TRACK]


def test_cvat_reads_the_stretch_back_as_outside() -> None:
    out = io.BytesIO()
    label = object_label("object 1")
    with CvatVideoWriter(out, [label], num_frames=FRAMES, width=64, height=96) as writer:
        writer.add_track("object 1", [mark_outside(TRACK, OUTSIDE), TRACK])
    xml = out.getvalue().decode()
    assert 'frame="3"' in xml and 'outside="1"' in xml
    [track] = read_cvat_video(io.BytesIO(out.getvalue())).tracks
    first = dense_track(track.keyframes[0], FRAMES)
    assert not np.isfinite(first.xy[3:6]).any() and np.isfinite(first.xy[6:]).all()
    assert np.isfinite(dense_track(track.keyframes[1], FRAMES).xy[1:]).all()
