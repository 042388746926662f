"""A camera's own fault as QC sees it in its labels: a lag in whole frames (found for all views
together) and a systematic image offset (worker.quality.view_offset), each taken out of the
view's labels before anyone is scored and reported on the camera, never charged to its workers.
"""

from __future__ import annotations

import warnings

import numpy as np

from worker.geometry.cameras import CameraModel
from worker.quality.consensus_fit import Fit
from worker.quality.hand_report import HandReport
from worker.quality.metrics import num
from worker.quality.view_labels import ViewLabels, decided_of
from worker.quality.view_offset import (
    MAX_LAG_FRAMES,
    ViewOffset,
    fit_view_offset,
    shift_frames,
    vacated_frames,
)
from worker.rig.timing import joint_offsets


def camera_offsets(cameras: list[CameraModel], labels: list[ViewLabels], fit: Fit,
                    frames: int, lags: dict[int, int] | None = None,
                    corrected: Fit | None = None, silent: frozenset[str] = frozenset()
                    ) -> tuple[dict[int, ViewOffset], dict[int, int]]:
    """Per view, its lag (whole frames) and the map fitted to (leave-one-out reference,
    observation) of every label of the view over every point it is judged on (two other
    views fix it), the label shifted by the lag.

    fit: the labels as sent (``fit.pixels`` their observations). lags: given, they are
    taken as found. corrected: the fit of the labels already corrected (shifted by ``lags``
    and taken back through a first map): the references are then its leave-one-out ones
    (which the view's own correction does not touch), the observations still those sent.
    silent: keys of labels their own evidence discredits: they take no part in finding the
    lags (a view of only such labels keeps lag 0)."""
    source = fit if corrected is None else corrected
    judged = np.isfinite(source.spread).all(axis=(-1, -2)) & np.isfinite(source.loo).all(axis=-1)
    pairs: dict[int, list[tuple[np.ndarray, np.ndarray]]] = {}
    for col, lab in enumerate(labels):
        if corrected is None:
            obs = np.where(judged[:, col, None], fit.pixels[:, col], np.nan)
            ref = obs - fit.loo[:, col]
        else:
            ref = np.where(judged[:, col, None], corrected.pixels[:, col] - corrected.loo[:, col],
                           np.nan)
            obs = fit.pixels[:, col]
        pairs.setdefault(lab.view, []).append((ref.reshape(frames, -1, 2),
                                               obs.reshape(frames, -1, 2)))
    if lags is None:
        lags = dict.fromkeys({lab.view for lab in labels}, 0)
        lags.update(view_lags(cameras, [lab for lab in labels if lab.key not in silent],
                              frames))
    # The corrected fit's references are already in the frames the view's images show.
    offsets = {view: fit_view_offset(view, [(r, shift_frames(o, lags.get(view, 0)))
                                            for r, o in found], cameras[view].K[:2, 2])
               for view, found in pairs.items()}
    return offsets, lags


# A view's lag is kept where its own cost there is below this share of the cost at 0: looser
# than the rig's (worker.rig.timing.OFFSET_GAIN) because a QC view is often one worker's
# clicks on a short clip, whose noise (2-3 px) is near one frame's motion; on a sound camera
# the wrong lags cost 1.5-4x the right one.
LAG_GAIN = 0.9


def view_lags(cameras: list[CameraModel], labels: list[ViewLabels],
               frames: int) -> dict[int, int]:
    """Per labelled view, the whole frames (|k| <= MAX_LAG_FRAMES) by which its images are out
    of step (a camera one frame late: -1), chosen for all views together (worker.rig.timing)
    with the lowest labelled view's time held: judged one view at a time against the others,
    two late views of four split the references two against two and the sound ones look
    early. Each view's observation is the median of its labels' decided visible positions."""
    views = sorted({lab.view for lab in labels})
    if len(views) < 3:
        return dict.fromkeys(views, 0)
    pixels = np.full((len(views), frames, labels[0].xy.shape[1], 2), np.nan)
    for i, view in enumerate(views):
        own = [np.where((lab.visible & decided_of(lab))[..., None], lab.xy, np.nan)
               for lab in labels if lab.view == view]
        with warnings.catch_warnings():
            # A cell no label of the view decided stays NaN (nanmedian warns of it).
            warnings.simplefilter("ignore", RuntimeWarning)
            pixels[i] = np.nanmedian(np.stack(own), axis=0) if len(own) > 1 else own[0]
    found = joint_offsets([cameras[v] for v in views], pixels, MAX_LAG_FRAMES, fixed=(0,),
                          gain=LAG_GAIN)
    # A late camera (offset k = 1: its frame f shows world time f - 1) has lag -1.
    return {view: -int(k) for view, k in zip(views, found, strict=True)}


def offset_corrected(lab: ViewLabels, offset: ViewOffset, lag: int) -> ViewLabels:
    """The label re-indexed to the frames its images show and taken back through the map;
    frames left without a position of their own are not the worker's decision there."""
    xy, visible = shift_frames(lab.xy, lag), shift_frames(lab.visible, lag)
    decided = shift_frames(decided_of(lab), lag) & ~vacated_frames(len(xy), lag)[:, None] \
        if lag else lab.decided
    return ViewLabels(lab.key, lab.view, offset.correct(xy), visible, lab.working_time_s,
                      decided)


def report_offsets(report: HandReport, offsets: dict[int, ViewOffset],
                    lags: dict[int, int]) -> None:
    """The camera offsets and lags on the report, each one found in its labels' metrics, and
    the replay's references taken back to the view's own pixels and frames."""
    report.camera_offsets, report.camera_lags = offsets, lags
    for key, qc in report.assignments.items():
        offset, lag = offsets.get(qc.view), lags.get(qc.view, 0)
        if lag:
            qc.metrics["camera_lag_frames"] = float(lag)
        if offset is not None and offset.applied:
            qc.metrics["camera_offset_px"] = num(offset.offset_px, 2)
        if key in report.replay and offset is not None:
            replay = report.replay[key]
            replay["reference"] = shift_frames(offset.forward(replay["reference"]), -lag)
            replay["errors"] = shift_frames(replay["errors"], -lag)
