"""What the solver takes and returns: targets, inputs, settings and the per-frame result.

Frames: world = the capture's master frame; cameras are `CameraModel`s (camera-to-world 3x4,
metres). Pixels are x right, y down. Lengths are metres unless a name says mm or px.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from worker.geometry.cameras import CameraModel
from worker.hand.params import HandModel

# Visible keyed joints a frame of one view needs before the hand model can be fitted to it and
# followed through the view's depth (worker.solver.follow; as the solve's min_joints: fewer
# leave the pose under-determined). Here, without PyTorch, so that the API can say so.
FOLLOW_START_JOINTS = 6


@dataclass
class HandTarget:
    """One hand's crowd labels over V views and F frames.

    side: "right" or "left". betas: (10,) subject shape, fixed.
    keypoints: (V, F, 21, 2) px in DexYCB joint order, NaN where there is no label.
    visible: (V, F, 21) bool, the annotator's visibility flag (gamma in the paper).
    evidence: optional (V, F, 21) int8 codes of how each label was decided
        (worker.assist.stretches.EVIDENCE_*: keyed, interpolated and confirmed by the
        view's images, interpolated unchecked, contradicted); None: every label counts as
        keyed (labels without provenance). Read by the hand's confidence only.
    """

    side: str
    betas: np.ndarray
    keypoints: np.ndarray
    visible: np.ndarray
    evidence: np.ndarray | None = None


@dataclass
class Landmark:
    """One worker-chosen object landmark, tracked in one view.

    view: index into the cameras. xy: (F, 2) px, NaN where there is none. visible: (F,) bool.
    """

    view: int
    xy: np.ndarray
    visible: np.ndarray


@dataclass
class ObjectTarget:
    """One rigid object: its mesh (object frame, metres), pose at frame 0 and landmarks.

    vertices: (N, 3) metres. faces: (M, 3) int. initial_pose: (3, 4) object-to-world at frame 0;
    None: fitted to frame 0's depth and landmarks, the solve refused where that fit fails.
    landmarks: usually 2 per view.
    """

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    initial_pose: np.ndarray | None
    landmarks: list[Landmark] = field(default_factory=list)


@dataclass
class SolveInputs:
    """Everything one sequence's solve needs.

    cameras: V calibrated views. num_frames: F. depth: per view (F, H, W) uint16 millimetres
    along the camera's z (0 = no depth), aligned to colour, or None. hand_model: a
    `worker.hand.HandModel`; None means the built-in model of the hand's side.
    """

    cameras: list[CameraModel]
    num_frames: int
    hand: HandTarget | None
    objects: list[ObjectTarget]
    depth: list[np.ndarray | None]
    hand_model: HandModel | None = None


@dataclass
class SolveSettings:
    """Energy weights and optimiser choice.

    Energies (per frame): E = w_kpt E_kpt + w_depth E_depth + w_reg E_reg (+ w_smooth E_smooth
    + w_smooth_pose E_smooth_pose for the default optimiser). E_kpt in px^2 (visibility-weighted
    mean squared reprojection error), E_depth in mm^2 (mean squared distance of depth points to
    the union of meshes), E_reg in rad^2 (squared norm of the 45 PCA pose coefficients),
    E_smooth in mm^2 (squared distance of the 3D joints to their two neighbouring frames' mean),
    E_smooth_pose in rad^2 (the same for the 45 PCA pose coefficients).

    The paper gives no weights. w_kpt and w_depth are roughly inverse noise variances: crowd
    labels are good to ~3 px (9 px^2), a D415 measures ~1 mm at 0.7 m, so a squared mm of depth
    counts about ten times a squared pixel (bench/solve.py: w_depth 1 -> 10 cut the hand's MPJPE
    from ~1.4 to ~0.9 mm on 24 frames). E_kpt is a mean over all of a frame's labels, so a
    prior of w_reg 10 towards the mean pose weighs as much as ~10 px^2 on every label: it held a
    grasping hand's fingers open, the little fingertip 3.5 mm off with exact labels (capture
    seed 57). The prior now pulls each frame's pose coefficients mostly towards its neighbours'
    (w_smooth_pose), which a steadily closing hand satisfies, and only weakly towards the mean
    pose (w_reg). With 3 px labels that took seed 57 from 1.33 to 1.04 mm MPJPE (w_reg 1:
    1.29 mm alone). Smoothing the joints themselves (w_smooth) penalises the hand's
    acceleration as a whole, which at 30 fps is larger than the noise it removes: it made
    MPJPE worse (1.29 -> 1.36 mm at 0.03) and stays off.

    optimiser: "paper" = Adam (lr, paper_iterations per frame, warm start from the previous
    frame, depth matches renewed every paper_rematch_every iterations); "default" = batched
    Levenberg-Marquardt from triangulation, lm_iterations per (robust) round, icp_rounds
    rounds of renewed depth matches.
    min_views: a frame is solved for the hand only where at least `min_joints` joints are
    labelled visible in at least `min_views` views each.
    robust_scale_px: Cauchy scale of the robust keypoint loss (default optimiser, robust=True);
    depth_robust_mm: the same for depth matches, by their distance when matched.
    depth_stride: take every n-th depth pixel in x and y. depth_margin: keep depth points within
    this distance (m) of a current mesh's box. max_depth_points: per frame, random subset.
    """

    optimiser: Literal["paper", "default"] = "default"
    device: str = "cpu"
    w_kpt: float = 1.0
    w_depth: float = 10.0
    w_reg: float = 1.0
    w_smooth: float = 0.0
    w_smooth_pose: float = 40.0
    robust: bool = True
    robust_scale_px: float = 8.0
    depth_robust_mm: float = 5.0
    min_views: int = 2
    min_joints: int = 6
    lr: float = 0.01
    paper_iterations: int = 100
    paper_rematch_every: int = 1
    lm_iterations: int = 4
    icp_rounds: int = 2
    depth_stride: int = 4
    depth_margin: float = 0.02
    workspace_margin: float = 0.5
    max_depth_points: int = 1500
    use_depth: bool = True
    seed: int = 0


@dataclass
class SolveResult:
    """Per-frame solution, world frame.

    hand_pose_m: (F, 51) DexYCB pose_m (3 global axis-angle, 45 PCA coefficients with
    flat_hand_mean False, 3 translation in metres), NaN rows where the hand is unlabelled.
    hand_joints: (F, 21, 3) metres, NaN where unlabelled. object_poses: (O, F, 3, 4)
    object-to-world. labelled: (F,) bool. reasons: per frame None or why it is unlabelled.
    kpt_error_px: (F, V, 21) reprojection error of each labelled visible joint, NaN elsewhere.
    depth_rms_mm: (F,) RMS distance of the cropped depth points to the meshes (NaN: none).
    landmark_vertices: per object, per landmark the vertex id it was mapped to (-1 if it could
    not be): ids from the mesh's vertex count on are surface points added for landmarks.
    landmark_points: per object, per landmark that surface point (3,) in the object's frame,
    metres (None if unmapped). timings: seconds per stage.
    object_confidence: (O, F) in [0, 1], how well each object pose is supported by its
    evidence (see `worker.solver.confidence`). object_flags: per object, per frame None or the
    reason that pose is not trusted; a flagged pose is exported as unlabelled.
    hand_confidence: (F,) in [0, 1], how well the evidence pins each frame's hand down;
    hand_flags: (F,) None or the reason the frame's hand is not trusted (see
    `worker.solver.hand_confidence`); empty when there is no hand.
    """

    hand_pose_m: np.ndarray
    hand_joints: np.ndarray
    object_poses: np.ndarray
    labelled: np.ndarray
    reasons: list[str | None]
    kpt_error_px: np.ndarray
    depth_rms_mm: np.ndarray
    landmark_vertices: list[list[int]]
    timings: dict[str, float]
    landmark_points: list[list[list[float] | None]] = field(default_factory=list)
    betas: np.ndarray | None = None
    side: str | None = None
    object_confidence: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    object_flags: list[list[str | None]] = field(default_factory=list)
    hand_confidence: np.ndarray = field(default_factory=lambda: np.zeros(0))
    hand_flags: list[str | None] = field(default_factory=list)

    def to_summary(self) -> dict:
        """JSON-friendly summary: counts, error statistics (px, mm), timings (s)."""
        kpt = self.kpt_error_px[np.isfinite(self.kpt_error_px)]
        depth = self.depth_rms_mm[np.isfinite(self.depth_rms_mm)]

        def stat(values: np.ndarray) -> float | None:
            return float(values) if np.isfinite(values) else None

        return {
            "frames": int(self.labelled.shape[0]),
            "labelled_frames": int(self.labelled.sum()),
            "unlabelled": {str(f): r for f, r in enumerate(self.reasons) if r is not None},
            "kpt_error_px_mean": stat(kpt.mean()) if kpt.size else None,
            "kpt_error_px_median": stat(np.median(kpt)) if kpt.size else None,
            "depth_rms_mm_mean": stat(depth.mean()) if depth.size else None,
            "landmark_vertices": [list(map(int, v)) for v in self.landmark_vertices],
            "landmark_points": self.landmark_points,
            "timings": {k: float(v) for k, v in self.timings.items()},
            "flagged_object_frames": [sum(r is not None for r in flags)
                                      for flags in self.object_flags],
            "object_flags": {f"{o}:{f}": r for o, flags in enumerate(self.object_flags)
                             for f, r in enumerate(flags) if r is not None},
        }
