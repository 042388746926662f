"""Follow a hand through one view's depth from a worker's keyframes: proposals for a first view.

Tracking image patches (worker.assist.lk) loses most hand joints within a clip: skin has little
texture, and a joint drifts along a finger without failing any check. One view's depth sees the
hand's surface in every frame, though, and the hand model (bone lengths, joint limits, pose
prior) ties the 21 joints together. So the hand model is fitted to the worker's keyframes of
the first frame it keyed (at least MIN_START_JOINTS visible joints), lifted onto the view's
depth (from a few start guesses, each fitted a few ways: the fit the depth supports best that
sits on the keyframes starts), and then carried frame by frame forward to the end of the clip
and backward to its start: each frame starts from the previous frame's pose with its velocity
added (and, where the depth fits that worse than usual, from a few other shares of it: a hand
that stops or turns) and is fitted to that frame's depth (ICP rounds: the depth points near the
hand matched to its surface, worker.solver.problem.Problem.match_depth, robustly weighted) and
to whatever the worker keyed at that frame (the keypoint term, robust), its pose coefficients
pulled towards the previous frame's (the fingers the view does not see keep their bend). A
frame keyed by the worker again pulls the hand back where it had drifted, so a correction mends
what follows it: asked again from a corrected frame (``begin``), the follow is both carried
from the same first keyed frame through every keyframe and accepted proposal before the
correction and started afresh from the corrected frame's keys, and the one the depth fits
better is kept: a start in the grasp, where the keys lift onto the object, can be worse than
the open hand's carried there, and a first start from noisy clicks worse than the worker's
corrected frame. Depth readings that have not changed since the keyed frame (the table, an
object still at rest) are left out of the matches, outside the hand's own pixels there; so are
those of what the hand holds once it moves: the readings beside the fitted hand are carried to
the next frame with the palm's rigid motion, and that frame's readings where they land are left
out (_Held).

The follow stops (in that direction) at the first frame whose fit the depth does not support:
fewer than MIN_MATCHED depth points near the fitted surface, or their robust RMS distance over
both MAX_DEPTH_RMS_MM and STOP_RATIO times the view's usual. It does not start at all where the
keyed frame's fit fails those (MAX_START_RMS_MM there) or lies more than MAX_START_PX from the
worker's keyframes. The proposals are the fitted joints projected into the view where they fall
inside the image; the worker's own keyframes stay as they are (the proposals fill between).

What it cannot do: a hand that moves much further from one frame to the next than it went
from the frame before (the next frame starts where the hand would be had it gone on at its
last velocity) and further than the depth matches reach from there is lost, and a hand that
slides or turns along its own surface can fit the depth well while its joints drift, so the
stop comes late; the worker looks at the ghosts before taking them. bench/follow.py measures
both.

Conventions as in worker.geometry.cameras: pixels x right, y down; world metres; depth (F, H,
W) uint16 millimetres along the camera's z axis, 0 = no reading. F frames of the clip given.
Pure: arrays in, arrays out (PyTorch through the solver).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np

from worker.assist.prefill import ViewWork
from worker.geometry.cameras import CameraModel, camera_to_world, pixels_to_rays
from worker.hand.joints import NUM_JOINTS
from worker.hand.params import HandModel
from worker.solver.default import fit_hand
from worker.solver.depth import DepthClouds, crop_to_boxes, match_points
from worker.solver.init import hand_from_joints, kabsch
from worker.solver.problem import Problem
from worker.solver.state import SolveState, hand_vertices_world
from worker.solver.suggest import START_ITERATIONS, lift_labels
from worker.solver.types import FOLLOW_START_JOINTS, HandTarget, SolveInputs, SolveSettings

# Visible keyed joints a frame needs before the hand model can start from it.
MIN_START_JOINTS = FOLLOW_START_JOINTS
# ICP rounds per frame (matches renewed, then LM); a frame stops early once the pose moves less
# than CONVERGED_M at any joint between rounds.
ROUNDS = 16
LM_ITERATIONS = 4
CONVERGED_M = 0.0003
# Share of the previous frame's velocity added to the start of the next frame's fit: the hand
# goes on as it went. A hand that speeds up outran half its velocity with 8 rounds: on s6262's
# start view (crowd seed 0) the hand moves 6-9 px a frame from frame 32, and the follow settled
# 3-6.6 px off for the next 30 frames at 1.5-2 mm depth RMS (inside the stop rule); with the
# whole velocity and up to 16 rounds it stays within 1.3 px there (bench/follow.py's worker: 140
# edits -> 54). On the test capture's every third frame (up to 26 px a frame) 0.5 against 14 px
# median.
VELOCITY = 1.0
# A hand that stops or turns back is overshot by its velocity: where a frame's fit comes out
# over RETRY_RATIO times the view's usual depth RMS, it is fitted again from the previous
# frame's pose plus each of RETRY_VELOCITY times its velocity, and the fit with the lowest RMS
# is kept.
RETRY_RATIO = 1.25
RETRY_VELOCITY = (0.0, 0.5, 1.5)
# Where the depth no longer supports the fit: too few depth points within the match margin of
# the fitted surface, or their robust RMS distance too large.
MIN_MATCHED = 40
MAX_DEPTH_RMS_MM = 2.5
# How well the depth fits differs by view (grazing angles, the sensor's noise at range): a frame
# also passes while its RMS is within STOP_RATIO times the median of the frames followed so far
# in that direction (the keyed frame's where there are none yet).
STOP_RATIO = 2.0
# The keyed frame is fitted from each start guess (_start_guesses) each of these ways: (LM
# iterations x robust rounds on the keyframes alone, then START_ROUNDS ICP rounds
# with the keypoint term this many times its weight). Of the fits within MAX_START_PX of the
# keyframes, the one with the lowest robust depth RMS starts the follow. The first is the plain
# fit; in the second the depth places the hand along the rays while the keyframes hold the
# fingers where the worker put them; in the third the depth leads. One draw of 2 px clicks
# decides which is best: on s7717's sixth view (first frame keyed, crowd seed 3) the first two
# ways from the one guess started at 5.6 mm RMS and were refused; with three guesses, three
# ways and 4x the rounds the start fitted 1.4 mm and the next 9 frames followed at 0.9 px
# median, and with 3x the follow there runs to frame 53 (63 edits in bench/follow.py's worker
# against 147 tracking alone).
# The fourth goes to the depth straight from the guess. A fit to the keyframes alone places
# the hand along the rays by its size in the image, and on a hand 50-60 px across 2 px clicks
# change that size by a few percent: the hand came 13-25 mm too near, where the back of the
# model's fingers lay on the skin the camera sees, and no ICP round brought it back (s6262's
# fifth view, 850 mm away, first frame keyed: 3 of 4 click draws started there at 2.5-3.4 mm
# RMS, a third of the model's surface more than 10 mm in front of the depth, and followed
# 6.5 px off). Fitted from the lifted guess, which the depth holds near the skin, two of them
# started at 1.60-1.64 mm and followed frames 0-5 at 0.8-1.2 px median; the third still
# started at 2.45 mm, 6.6 px off (see PUSH_BACK_M).
DIRECT_FIT = (0, 0, 1.0)
START_FITS = ((LM_ITERATIONS, 2, 1.0), (20, 5, 5.0), (LM_ITERATIONS, 2, 0.3), DIRECT_FIT)
# The lifted guess itself can stand that far in front: the nearest reading around a keyed
# joint is often a finger before it (s6262's fifth view: wrist and thumb lifted 17-40 mm too
# near even from exact keys). The first guess is also tried pushed back along its ray by each
# of these (metres), fitted the direct way only (a fit to the keyframes first would bring it
# forward again): on that third draw the guess pushed 10-20 mm started at 1.6 mm.
PUSH_BACK_M = (0.01, 0.02, 0.03)
START_ROUNDS = 24
# At the keyed frame the worker's 2 px click noise pulls the model against the depth too: the
# start is refused only where the keyed hand is off the depth (keyframes on another hand, or
# beside it, or a hand closed on an object that moves with it). Starts that followed well
# fitted 0.5-2.8 mm (s7717, its 8 views, first frames keyed with 2 px noise); one keyed at
# frame 46 of its sixth view, in the grasp, fitted 4.3 mm and followed 6-36 px off without
# the depth ever stopping it.
MAX_START_RMS_MM = 3.0
# Nor does the model start where it cannot sit on the worker's own keyframes: the median of the
# keyed joints' distances (px) to the fitted ones over this (a hand the model cannot pose so,
# or keyframes that are not one hand).
MAX_START_PX = 8.0
# A lifted keyed joint this far (metres) from the hand fitted to all of them is left out of
# one start guess: a joint behind a finger is lifted onto that finger's surface.
OUTLIER_M = 0.015
# Every depth pixel (DEPTH_STRIDE 1), where the multi-view solve takes every 4th in x and y:
# one view is all the follow has, and a finger is a few pixels wide at arm's length, so at
# every 4th the fingertips got few matches or none and slid along their own surface while the
# depth RMS stayed low. On s7717's second and fifth views (crowd seed 3, first frame keyed)
# the joint-frames beyond the careful worker's tolerance or not proposed fell from 649 to 37
# (every 2nd: 507), at about 1.3x the time.
DEPTH_STRIDE = 1
SETTINGS = SolveSettings(min_views=1, min_joints=0, icp_rounds=1, depth_stride=DEPTH_STRIDE)

# The scene that does not move: a depth reading within STATIC_MM of the keyed frame's at the
# same pixel is the table or an object at rest, not the hand (outside the hand's own pixels at
# the keyed frame, grown by HAND_MASK_PX). Beside a finger such points would pull the hand.
STATIC_MM = 8
HAND_MASK_PX = 15
# A frame is fitted alone, so the solve's pull of each frame's pose towards its neighbours'
# mean has nothing to pull towards, and only the weak prior towards the mean (open) hand acted
# on the fingers the depth does not see (behind the others from that view): they opened while
# the hand closed on the object. Each frame's pose coefficients are pulled towards the previous
# frame's instead, with this weight (the solve's w_smooth_pose). On s5151's first view, keyed
# on frame 0 without noise, the frames before the lift (0-53) with 3 or more joints 6 px or
# more off the truth went from 30 to 8.
HELD_POSE_WEIGHT = 40.0

# What the hand holds moves with it, so the static scene no longer hides an object once lifted,
# and its surface beside the fingers pulled them onto it (s7717's fourth view, crowd seed 3:
# 4-9 joints 6 px or more off the truth on every frame from the lift, frame 54, at 2 mm depth
# RMS). So the readings beside the fitted hand (within the match margin of its surface, more
# than BESIDE_MM from it) that the static scene holds, or that were left out as held, are
# carried to the next frame with the hand's rigid motion, and that frame's readings within
# BESIDE_MM of where they land (along the pixel's ray) are left out of its matches. A reading of
# the hand's own that the fit left beside it is moving, so it is not carried: a finger fitted
# off its depth is still pulled back. With this and HELD_POSE_WEIGHT's pull, that view took 31
# edits in bench/follow.py's worker against 53.
BESIDE_MM = 6.0
# The hand's rigid motion from one frame to the next: that of its wrist and the fingers' roots,
# which the fingers' bending does not move. A carried point leaves out the readings within
# CARRY_PX pixels of where it lands.
PALM_JOINTS = [0, 5, 9, 13, 17]
CARRY_PX = 2
# Pixels around the hand's projected box searched for points beside it.
BESIDE_PAD_PX = 40

STOP_END = "end"
STOP_DEPTH = "depth"
STOP_KEYS = "keyframes"


@dataclass(frozen=True)
class Followed:
    """xy: (F, 21, 2) image px of the followed joints, NaN where not followed; ok: (F, 21) bool
    where a proposal is given (followed, inside the image); start: the keyed frame the follow
    started from (-1: none had MIN_START_JOINTS visible joints); stops: {"forward",
    "backward"} -> (frame where the follow stopped or -1, reason STOP_END/STOP_DEPTH, or
    STOP_KEYS where the model could not sit on the keyframes and nothing was followed);
    depth_rms_mm: (F,) per frame, NaN where not fitted."""

    xy: np.ndarray
    ok: np.ndarray
    start: int
    stops: dict[str, tuple[int, str]]
    depth_rms_mm: np.ndarray


class _Held:
    """What the hand holds, carried with it (BESIDE_MM). ``shown`` (F, H, W) is the depth the
    follow's clouds read: each frame's moving depth (``moving``) less the readings where the
    points beside the hand at the frame fitted before land, moved with the hand's palm.
    depth: (F, H, W) the view's depth as recorded; moving: the same less the static scene
    (_moving_depth); rays: (H * W, 3) its pixels' rays, in raster order."""

    def __init__(self, camera: CameraModel, depth: np.ndarray, moving: np.ndarray,
                 rays: np.ndarray) -> None:
        self.camera = camera
        self.depth = np.asarray(depth)
        self.source = moving
        self.shown = moving.copy()
        height, width = moving.shape[1:]
        if rays.shape != (height * width, 3):
            raise ValueError(f"expected a ray per pixel ({height * width}), got {rays.shape}")
        self.rays = rays.reshape(height, width, 3)
        self.left_out = np.zeros((height, width), bool)
        self.points = np.zeros((0, 3))
        self.palm: np.ndarray | None = None

    def forget(self) -> None:
        """Hold nothing (the follow turns back to its keyed frame)."""
        self.points, self.palm = np.zeros((0, 3)), None

    def snapshot(self, frame: int) -> tuple:
        """What is held and left out at ``frame`` now (restore puts it back)."""
        return (self.points, self.palm, self.left_out, self.shown[frame].copy())

    def restore(self, frame: int, saved: tuple) -> None:
        self.points, self.palm, self.left_out, self.shown[frame] = saved

    def leave_out(self, frame: int, joints: np.ndarray) -> None:
        """Before ``frame`` is matched with the hand's joints (21, 3) world as fitted so far."""
        height, width = self.left_out.shape
        self.left_out = np.zeros((height, width), bool)
        if self.palm is not None and len(self.points):
            rot, shift = kabsch(self.palm[None], joints[PALM_JOINTS][None],
                                np.ones((1, len(PALM_JOINTS))))
            carried = self.points @ rot[0].T + shift[0]
            pix = np.rint(self.camera.project(carried)).astype(int)
            z_mm = self.camera.depth_of(carried) * 1000.0
            inside = ((pix[:, 0] >= 0) & (pix[:, 0] < width) & (pix[:, 1] >= 0)
                      & (pix[:, 1] < height) & (z_mm > 0))
            pix, z_mm = pix[inside], z_mm[inside]
            if len(pix):
                # Within the landing points' box only (grown by CARRY_PX).
                x0, y0 = np.maximum(pix.min(0) - CARRY_PX, 0)
                x1, y1 = np.minimum(pix.max(0) + CARRY_PX + 1, (width, height))
                near = np.full((y1 - y0, x1 - x0), np.inf, np.float32)
                np.minimum.at(near, (pix[:, 1] - y0, pix[:, 0] - x0), z_mm.astype(np.float32))
                spread = cv2.erode(near, np.ones((2 * CARRY_PX + 1,) * 2, np.uint8))
                reading = self.source[frame, y0:y1, x0:x1].astype(np.float32)
                self.left_out[y0:y1, x0:x1] = (reading > 0) \
                    & (np.abs(reading - spread) < BESIDE_MM)
        self.shown[frame] = np.where(self.left_out, 0, self.source[frame])

    def note(self, frame: int, problem: Problem, vertices: np.ndarray, joints: np.ndarray
             ) -> None:
        """After ``frame`` is fitted (the hand's vertices (N, 3) and joints (21, 3) world, the
        problem's hand tree refitted to them): the readings beside the hand there that the
        static scene holds or that were carried there are what it holds."""
        height, width = self.left_out.shape
        pix = self.camera.project(vertices)
        pix = pix[np.isfinite(pix).all(axis=1)]
        if not len(pix) or problem.hand_tree is None:
            self.forget()
            return
        x0, y0 = np.clip(np.floor(pix.min(0)).astype(int) - BESIDE_PAD_PX, 0, None)
        x1, y1 = np.ceil(pix.max(0)).astype(int) + BESIDE_PAD_PX
        x1, y1 = min(int(x1), width), min(int(y1), height)
        reading = self.depth[frame, y0:y1, x0:x1].astype(np.int32)
        # The static scene: what the moving depth left out (never the hand's own pixels at the
        # keyed frame, whose reading there is the hand's).
        static = self.source[frame, y0:y1, x0:x1] == 0
        ys, xs = np.nonzero((reading > 0) & (static | self.left_out[y0:y1, x0:x1]))
        z = reading[ys, xs].astype(np.float64) * 1e-3
        rays = self.rays[ys + y0, xs + x0]
        world = camera_to_world(rays * z[:, None], self.camera.T_cam_to_world)
        margin = problem.settings.depth_margin
        world = crop_to_boxes(world, [(vertices.min(0), vertices.max(0))], margin)
        found = match_points(world, [problem.hand_tree], [None], margin)
        self.points = found.points[found.dist > BESIDE_MM * 1e-3]
        self.palm = joints[PALM_JOINTS].copy()


def _fit_frame(problem: Problem, state: SolveState, frame: int, rounds: int,
               prior: np.ndarray | None = None, held: _Held | None = None
               ) -> tuple[int, float]:
    """Fit one frame's pose in place (keypoints where keyed, depth); (depth points matched,
    their robust RMS distance in mm) after the last round. prior: (45,) pose coefficients the
    frame's are pulled towards (HELD_POSE_WEIGHT), or None; held: what the hand holds, left
    out of each round's matches (None: nothing)."""
    state.hand_frames = np.array([frame])
    robust_mm = problem.settings.depth_robust_mm
    # The joints of the pose as it stands (what the held readings are carried with).
    joints = state.joints(problem)[0]
    before = None
    for _ in range(rounds):
        vertices = hand_vertices_world(problem, state.hand_pose[[frame]])[0]
        if held is not None:
            held.leave_out(frame, joints)
        matches = problem.match_depth(frame, vertices, np.zeros((0, 3, 4)))
        data = problem.depth_data(0, [matches], problem.hand_faces, robust_mm)
        fit_hand(problem, state, data, LM_ITERATIONS, 1,
                 None if prior is None else (prior[None], HELD_POSE_WEIGHT))
        joints = state.joints(problem)[0]
        if before is not None and np.abs(joints - before).max() < CONVERGED_M:
            break
        before = joints
    vertices = hand_vertices_world(problem, state.hand_pose[[frame]])[0]
    if held is not None:
        held.leave_out(frame, joints)
    matches = problem.match_depth(frame, vertices, np.zeros((0, 3, 4)))
    if held is not None:
        held.note(frame, problem, vertices, joints)
    if matches is None or not len(matches.dist):
        return 0, float("inf")
    dist_mm = matches.dist * 1000.0
    weight = 1.0 / (1.0 + (dist_mm / robust_mm) ** 2)
    rms = float(np.sqrt(np.sum(weight * dist_mm ** 2) / max(np.sum(weight), 1e-9)))
    return len(dist_mm), rms


def _fit_moving(problem: Problem, state: SolveState, frame: int, rounds: int,
                prior: np.ndarray, held: _Held, usual: float, guesses: list[np.ndarray]
                ) -> tuple[int, float]:
    """Fit a followed frame (_fit_frame, pulled towards ``prior``) from the first of
    ``guesses`` (pose_m (51,) each) and, where its depth RMS comes out over RETRY_RATIO times
    ``usual`` (mm), from the others as well: of those with MIN_MATCHED depth points, the fit
    with the lowest RMS is kept (its pose in ``state``, what is held as it left it). (depth
    points matched, their robust RMS mm) of the fit kept."""
    best: tuple[float, int, float, np.ndarray, tuple] | None = None
    before = held.snapshot(frame)
    for guess in guesses:
        if best is not None and best[0] <= RETRY_RATIO * usual:
            break
        state.hand_pose[frame] = guess
        count, rms = _fit_frame(problem, state, frame, rounds, prior, held)
        rank = rms if count >= MIN_MATCHED else np.inf
        if best is None or rank < best[0]:
            best = (rank, count, rms, state.hand_pose[frame].copy(), held.snapshot(frame))
        held.restore(frame, before)
    assert best is not None
    _, count, rms, state.hand_pose[frame], after = best
    held.restore(frame, after)
    return count, rms


def _start_guesses(problem: Problem, camera: CameraModel, depth: np.ndarray,
                   keypoints: np.ndarray, visible: np.ndarray, start: int) -> list[np.ndarray]:
    """pose_m (1, 51) guesses of the keyed frame's hand, from its keyed joints (keypoints
    (21, 2) px, visible (21,) bool) lifted onto the depth: every lifted joint; the same less
    those more than OUTLIER_M from the hand fitted to them all (a joint behind a finger lifted
    onto that finger); and every keyed ray at the lifted joints' median depth (a flat hand that
    the keypoints and the depth then bend)."""
    keyed = np.full((1, NUM_JOINTS, 2), np.nan)
    keyed[0, visible] = keypoints[visible]
    frame = np.asarray(depth[start])[None]
    work = ViewWork(view=0, xy=keyed, visible=visible[None], decided=visible[None])
    lifted, ok = lift_labels([camera], [work], {0: frame})
    guesses = [hand_from_joints(problem, lifted, ok, START_ITERATIONS)]
    state = SolveState.empty(problem)
    state.hand_pose[[start]] = guesses[0]
    state.hand_frames = np.array([start])
    off = np.linalg.norm(state.joints(problem)[0] - lifted[0], axis=-1)
    kept = ok & ~(off > OUTLIER_M)[None]
    if kept.sum() >= MIN_START_JOINTS and kept.sum() < ok.sum():
        guesses.append(hand_from_joints(problem, lifted, kept, START_ITERATIONS))
    if ok.any():
        z = float(np.median(camera.depth_of(lifted[ok])))
        rays = pixels_to_rays(keypoints[visible], camera.K, camera.dist) * z
        flat = np.full((1, NUM_JOINTS, 3), np.nan)
        flat[0, visible] = camera_to_world(rays, camera.T_cam_to_world)
        guesses.append(hand_from_joints(problem, flat, visible[None], START_ITERATIONS))
    return guesses


def _pushed_back(problem: Problem, camera: CameraModel, guess: np.ndarray, start: int
                 ) -> list[np.ndarray]:
    """The guess (pose_m (1, 51)) moved each of PUSH_BACK_M further from the camera along the
    ray through its joints' centre."""
    state = SolveState.empty(problem)
    state.hand_pose[[start]] = guess
    state.hand_frames = np.array([start])
    ray = state.joints(problem)[0].mean(axis=0) - np.asarray(camera.T_cam_to_world)[:, 3]
    ray /= np.linalg.norm(ray)
    out = []
    for metres in PUSH_BACK_M:
        pushed = np.array(guess, np.float64)
        pushed[:, 48:] += metres * ray
        out.append(pushed)
    return out


def _start_rank(found: tuple[int, float, float, np.ndarray]) -> tuple[bool, float]:
    """Sort key of a fitted start (depth points matched, their RMS mm, median px from the
    keyframes, pose): first those with enough matches that sit on the keyframes, then the
    lowest depth RMS."""
    count, rms, off_px, _ = found
    return (not (count >= MIN_MATCHED and off_px <= MAX_START_PX), rms)


def _moving_depth(camera: CameraModel, depth: np.ndarray, start: int,
                  vertices: np.ndarray) -> np.ndarray:
    """(F, H, W) the depth without the static scene (STATIC_MM of the keyed frame ``start``'s
    reading), outside the hand's pixels at ``start`` (its vertices (N, 3) world) grown by
    HAND_MASK_PX; the keyed frame itself as it is."""
    depth = np.asarray(depth)
    height, width = depth.shape[1:]
    hand = np.zeros((height, width), np.uint8)
    pix = np.rint(camera.project(vertices)).astype(int)
    inside = (pix[:, 0] >= 0) & (pix[:, 0] < width) & (pix[:, 1] >= 0) & (pix[:, 1] < height)
    hand[pix[inside, 1], pix[inside, 0]] = 1
    size = 2 * HAND_MASK_PX + 1
    hand = cv2.dilate(hand, np.ones((size, size), np.uint8)).astype(bool)
    base = depth[start].astype(np.int32)
    static = (np.abs(depth.astype(np.int32) - base[None]) < STATIC_MM) & (base[None] > 0) \
        & ~hand[None]
    static[start] = False
    return np.where(static, 0, depth).astype(depth.dtype)


def follow_hand(camera: CameraModel, depth: np.ndarray, keypoints: np.ndarray,
                visible: np.ndarray, side: str, betas: np.ndarray,
                hand_model: HandModel | None = None, rounds: int = ROUNDS,
                begin: int | None = None) -> Followed:
    """The hand model carried through one view's depth from the worker's keyframes.

    keypoints: (F, 21, 2) px of the worker's keyed visible joints (NaN elsewhere); visible:
    (F, 21) bool, those keyed visible; depth: (F, H, W) uint16 mm of the same frames.
    begin: a correction: proposals only from ``begin`` on, forward (what comes before it stays
    as it was). The follow still starts where it would without ``begin`` (the first frame with
    MIN_START_JOINTS keyed joints) and is carried forward through the keyframes before
    ``begin``, which hold it where the worker placed or accepted the hand; it is also started
    afresh from the first such frame at or after ``begin`` (the corrected frame), and of the two
    that reach ``begin`` and sit within MAX_START_PX (median) of the corrected frame's keys, the
    one the depth fits better from ``begin`` on (mean robust RMS) is kept. None: from the first
    such frame, forward and backward.
    """
    keypoints = np.asarray(keypoints, np.float64)
    visible = np.asarray(visible, bool) & np.isfinite(keypoints).all(axis=-1)
    frames = keypoints.shape[0]
    if keypoints.shape != (frames, NUM_JOINTS, 2) or visible.shape != (frames, NUM_JOINTS):
        raise ValueError(f"expected keypoints (F, {NUM_JOINTS}, 2) and visible (F, "
                         f"{NUM_JOINTS}), got {keypoints.shape} and {visible.shape}")
    if np.shape(depth)[0] != frames:
        raise ValueError(f"depth has {np.shape(depth)[0]} frames, the keyframes {frames}")
    keyed = np.flatnonzero(visible.sum(axis=1) >= MIN_START_JOINTS)
    # The frame a correction was keyed on: the first keyed whole at or after ``begin``.
    corrected = keyed[keyed >= begin][:1] if begin is not None else keyed[:0]
    starts = list(dict.fromkeys(int(k) for k in (*keyed[:1], *corrected)))
    if not starts:
        return Followed(np.full((frames, NUM_JOINTS, 2), np.nan),
                        np.zeros((frames, NUM_JOINTS), bool), -1, {}, np.full(frames, np.nan))
    inputs = SolveInputs(
        cameras=[camera], num_frames=frames,
        hand=HandTarget(side=side, betas=np.asarray(betas, np.float64),
                        keypoints=keypoints[None], visible=visible[None]),
        objects=[], depth=[np.asarray(depth)], hand_model=hand_model)
    problem = Problem(inputs, SETTINGS)
    clouds = problem.clouds
    assert clouds is not None
    if begin is None:
        return _follow_from(problem, camera, depth, clouds, starts[0], rounds, backward=True)
    found: Followed | None = None
    for start in starts:
        candidate = _follow_from(problem, camera, depth, clouds, start, rounds, backward=False)
        candidate.xy[:begin] = np.nan
        candidate.ok[:begin] = False
        holds = candidate.ok.any() and all(
            _off_keys_px(candidate.xy[k], keypoints[k], visible[k]) <= MAX_START_PX
            for k in corrected)
        if holds and (found is None or _mean_rms(candidate, begin) < _mean_rms(found, begin)):
            found = candidate
    # Neither holds: the last one's answer says why (refused, or where it stopped).
    return candidate if found is None else found


def _mean_rms(found: Followed, begin: int) -> float:
    """The follow's mean robust depth RMS (mm) over the frames it fitted from ``begin`` on."""
    rms = found.depth_rms_mm[begin:]
    rms = rms[np.isfinite(rms)]
    return float(rms.mean()) if len(rms) else np.inf


def _off_keys_px(xy: np.ndarray, keypoints: np.ndarray, visible: np.ndarray) -> float:
    """Median px from one frame's keyed visible joints (keypoints (21, 2), visible (21,)) to
    the followed ones there (xy (21, 2), NaN where not followed: inf)."""
    off = np.linalg.norm(xy - keypoints, axis=-1)[visible]
    return float(np.median(np.where(np.isfinite(off), off, np.inf))) if len(off) else np.inf


def _follow_from(problem: Problem, camera: CameraModel, depth: np.ndarray,
                 clouds: DepthClouds, start: int, rounds: int, backward: bool) -> Followed:
    """follow_hand from the keyed frame ``start``, forward and, with ``backward``, backward
    (problem: the view's; its clouds set here: ``clouds``, the whole depth's, for the start,
    then the moving depth's)."""
    keypoints, visible = problem.keypoints[0], problem.gamma[0]
    frames = int(keypoints.shape[0])
    xy: np.ndarray = np.full((frames, NUM_JOINTS, 2), np.nan)
    rms = np.full(frames, np.nan)
    problem.clouds = clouds
    state = SolveState.empty(problem)
    # The keyed frame, fitted from each start guess each way of START_FITS; of the fits that
    # sit on the keyframes (MAX_START_PX), the one the depth fits best is kept.
    best: tuple[int, float, float, np.ndarray] | None = None
    guesses = _start_guesses(problem, camera, np.asarray(depth), keypoints[start],
                             visible[start], start)
    starts = [(guess, START_FITS) for guess in guesses] + [
        (pushed, (DIRECT_FIT,)) for pushed in _pushed_back(problem, camera, guesses[0], start)]
    for initial, ways in starts:
        for iterations, key_rounds, weight in ways:
            state.hand_pose[[start]] = initial
            state.hand_frames = np.array([start])
            if key_rounds:
                fit_hand(problem, state, None, iterations, key_rounds)
            problem.settings = replace(SETTINGS, w_kpt=weight * SETTINGS.w_kpt)
            count, fit_rms = _fit_frame(problem, state, start, START_ROUNDS)
            problem.settings = SETTINGS
            off_px = _off_keys_px(camera.project(state.joints(problem)[0]),
                                  keypoints[start], visible[start])
            found = (count, fit_rms, off_px, state.hand_pose[start].copy())
            if best is None or _start_rank(found) < _start_rank(best):
                best = found
    assert best is not None
    count, rms[start], off_px, state.hand_pose[start] = best
    state.hand_frames = np.array([start])
    fitted = np.zeros(frames, bool)
    refused = STOP_DEPTH if count < MIN_MATCHED or rms[start] > MAX_START_RMS_MM else \
        STOP_KEYS if not off_px <= MAX_START_PX else None
    if refused is not None:
        # The keyed hand does not sit on the depth, or the model not on the keyframes.
        return Followed(xy, np.zeros((frames, NUM_JOINTS), bool), start,
                        {"forward": (start, refused), "backward": (start, refused)}, rms)
    stops: dict[str, tuple[int, str]] = {}
    fitted[start] = True
    held = _Held(camera, depth, _moving_depth(
        camera, depth, start, hand_vertices_world(problem, state.hand_pose[[start]])[0]),
        clouds.views[0][3])
    problem.clouds = DepthClouds([camera], [held.shown], SETTINGS.depth_stride)
    for name, step in (("forward", 1), ("backward", -1))[:2 if backward else 1]:
        stops[name] = (-1, STOP_END)
        # Nothing is held at the keyed frame: its reading is all moving depth (none static).
        held.forget()
        history: list[float] = []
        for f in range(start + step, frames if step > 0 else -1, step):
            prev = state.hand_pose[f - step]
            back = f - 2 * step
            older = state.hand_pose[back] if 0 <= back < frames and fitted[back] else prev
            usual = float(np.median(history)) if history else float(rms[start])
            count, rms[f] = _fit_moving(problem, state, f, rounds, prev[3:48].copy(), held, usual,
                                        [prev + share * (prev - older)
                                         for share in (VELOCITY, *RETRY_VELOCITY)])
            if count < MIN_MATCHED or rms[f] > max(MAX_DEPTH_RMS_MM, STOP_RATIO * usual):
                stops[name] = (f, STOP_DEPTH)
                break
            history.append(float(rms[f]))
            fitted[f] = True
    state.hand_frames = np.flatnonzero(fitted)
    joints = state.joints(problem)
    projected = camera.project(joints)
    inside = ((projected[..., 0] >= 0) & (projected[..., 0] < camera.width)
              & (projected[..., 1] >= 0) & (projected[..., 1] < camera.height)
              & np.isfinite(projected).all(axis=-1))
    xy[state.hand_frames] = np.where(inside[..., None], projected, np.nan)
    ok = np.isfinite(xy).all(axis=-1)
    return Followed(xy, ok, start, stops, rms)
