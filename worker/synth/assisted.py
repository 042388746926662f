"""Simulated assisted annotators: workers who take tracking proposals and pre-fill suggestions.

Conventions as in worker.synth.annotators: one camera view, F frames, P points, positions in
image px (x right, y down). A worker's output is P tracks of keyframe rows ``[frame, x, y,
visible01]`` (placed by hand) or ``[frame, x, y, visible01, source]`` with source one of

    tracked    an accepted tracking proposal (worker.assist.lk), unchanged;
    prefilled  an accepted pre-fill suggestion (the consensus of other views), unchanged;
    edited     came from a suggestion and the worker moved it or changed its visibility;

plus the actions it took. Every suggestion the worker is shown passes through the check cells
of its assignment first (worker.assist.checks.plant), exactly as the routes show them.

Action counting (the same rule for annotators.keyframe_actions, today's keyframe worker):
    click   placing a visible point on a frame (a new keyframe);
    key     one key press: marking a keyframe occluded (a new occluded keyframe), asking for
            tracking proposals (one per request, all points at once, as the route takes them),
            accepting the proposals shown (one per request), accepting the pre-fill (one for
            all points and frames), fixing a suggested visibility (one per keyframe);
    drag    moving a suggested point to where the worker sees it;
    navigation (changing frame or point, looking) is free.
keyframes_placed counts the keyframes made by hand (clicks and occluded keyframes).

The annotation page's own action counter (what it saves as ``edit_count``, and what
backend.progress.frame_costs sums) counts the worker's changes to the labels instead: every
click, drag (once, however many steps), occlusion key, Enter that takes proposals and U that
takes suggestions; asking for proposals (T) changes nothing and is not counted, nor is a
re-track the page writes by itself after a correction inside tracked keyframes (``writes``,
kept apart). ``Actions.edits`` is that count: clicks, drags and keys less the requests
(``requests``).

Assistance (the ``Assistance`` the worker is given): ``AssistSetting`` computes what the routes
show in process (worker.assist.lk, the check cells planted here); backend.crowd.simulate asks
the routes themselves over HTTP. Where a model follow is offered (``model_follow``:
worker.solver.follow, in process only) and there are no suggestions, the worker asks for it
after its first keyframes, takes it up to the first frame where MODEL_OFF_JOINTS of its ghosts
are off (the careful worker; the blind acceptor takes it all), drags the rest of what is off,
asks again from that frame where only a few are off there (fixing them first), and tracks
from where it stopped. With ``follows`` the worker keys no clip's last frame: it
follows each point forward from its last keyframe (the proposals route's ``follow``) and
corrects where the follow stopped or strayed. With ``retracks`` the page re-tracks around each
correction by itself (one write, no T and no Enter), as the annotation page does; without it
the worker asks again (T) and accepts (Enter) once a round for every point.

Workers:
    careful   clicks and drags to the truth plus its own Gaussian noise (CAREFUL_SIGMA_PX, one
              draw per frame and point) and judges a shown marker against where it sees the
              point: the truth plus a judging noise (JUDGE_SIGMA_PX, drawn apart). Keys by
              hand only what tracking cannot give (the first and last frame, each visibility
              change and the last visible frame before an occlusion), asks for proposals,
              accepts them, then looks at every frame
              between its keyframes: where the shown position (an accepted proposal, or the
              interpolation where LK found nothing) is more than TOLERANCE_PX from where it
              sees the point, it corrects the worst such frame of the span (a drag; a click
              where there was no proposal) and asks again for the two halves, until every
              frame is within tolerance or keyed. With a pre-fill that mostly sits on the
              points (TAKE_SHARE) it first accepts it, drags what is beyond tolerance, fixes
              wrong visibility, and tracks only the gaps; one that mostly does not, it leaves.
    blind     keys by hand what the careful worker keys (the first and last frame and the
              visibility changes, with the same care; the last frame even where points are
              followed), accepts every proposal and the whole pre-fill, corrects nothing: the
              check cells keep their offsets. Its labels are as good as the suggestions, so
              where those hold only the check cells tell it apart.

Pure numpy (and OpenCV through worker.assist.lk); every random choice comes from ``rng``.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal, Protocol

import numpy as np

from worker.assist import checks
from worker.assist.lk import follow, propose
from worker.synth.annotators import CAREFUL_SIGMA_PX
from worker.tracks.interpolate import dense_track

Source = Literal["placed", "tracked", "prefilled", "edited"]
# How far (px) a shown position may be from where the careful worker sees the point before it
# corrects it: 3 sigma of its click noise (the spread of its own keyframes), while a check cell
# (15 px off) is always corrected.
TOLERANCE_PX = 3.0 * CAREFUL_SIGMA_PX
# Noise (px, per axis) of the careful worker's judgement of where a point is when it compares
# a shown marker with the image: a comparison in place, without the motor noise of a click,
# taken as half the click noise. An assumption, not a measurement: bench/assist.py
# --judge-sigma 2 gives the cost of judging as noisily as clicking (more needless drags).
JUDGE_SIGMA_PX = 0.5 * CAREFUL_SIGMA_PX
# Share of the suggestions on points it sees that must sit within tolerance for the careful
# worker to take them (U) rather than label the view without them (_worth_taking).
TAKE_SHARE = 0.8
# The model follow (worker.solver.follow) starts from a frame keyed with this many visible
# joints (its MIN_START_JOINTS); the careful worker takes its ghosts up to the first frame
# where this many are off.
MODEL_START_JOINTS = 6
MODEL_OFF_JOINTS = 3
# Where at most this many are off at that frame, it drags them and asks the model again from
# there, up to MODEL_ROUNDS times in all while each round carries the hand at least
# MODEL_PROGRESS frames further; else it tracks on from the last frame taken.
MODEL_FIX_JOINTS = 8
MODEL_ROUNDS = 12
MODEL_PROGRESS = 2
# Rounds of asking for proposals after which the careful worker stops (each round halves or
# settles every open span; a 72-frame clip needs at most about log2(72) + a few).
MAX_ROUNDS = 20


@dataclass(frozen=True)
class Prefill:
    """Pre-fill suggestions for one view, before its check cells are planted.

    xy: (F, P, 2) image px, NaN where there is no suggestion.
    visible: (F, P) bool, the suggested visibility (from the view's depth); where it is not
        known the page takes the suggestion as visible, so pass True there.
    known: (F, P) bool, where the view's depth decided the visibility (None: everywhere).
        The route plants check cells wherever a suggestion has a position and is not known
        to be occluded (backend.labels.suggestions): the page shows those as visible.
    """

    xy: np.ndarray
    visible: np.ndarray
    known: np.ndarray | None = None

    def shown(self) -> np.ndarray:
        """(F, P) bool, where the route may plant a check cell: a position, shown visible."""
        has_xy = np.isfinite(self.xy).all(axis=2)
        return has_xy & np.asarray(self.visible, bool)


class Assistance(Protocol):
    """What the annotation page shows one assignment's worker, as its routes answer."""

    @property
    def frames(self) -> int: ...

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) px of the view."""
        ...

    @property
    def follows(self) -> bool:
        """Whether a point is followed forward from its last keyframe (the worker then keys
        no clip's last frame)."""
        ...

    @property
    def retracks(self) -> bool:
        """Whether the page re-tracks around a correction by itself (the annotation page)."""
        ...

    def proposals(self, anchors: list[list[list[Any]]], forward: list[int]
                  ) -> tuple[np.ndarray, np.ndarray]:
        """Proposals between each point's anchors (P lists of [frame, x, y, visible01] rows,
        empty for a point not asked about) and, for the points in ``forward``, after its last
        anchor: (F, P, 2) px as shown (check cells moved off) and (F, P) where they hold."""
        ...

    def suggestions(self) -> Prefill | None:
        """The view's suggestions as shown (check cells moved off), None when there are none."""
        ...

    def model_follow(self, anchors: list[list[list[Any]]], begin: int | None = None
                     ) -> tuple[np.ndarray, np.ndarray] | None:
        """The hand model carried through the view's depth from the keyframes given (P lists
        of [frame, x, y, visible01] rows, worker.solver.follow), forward only from ``begin``
        when given: (F, P, 2) px as shown (check cells moved off) and (F, P) where a proposal
        is given; None where the page offers no such follow."""
        ...


@dataclass(frozen=True)
class AssistSetting:
    """What the page gives one assignment, computed in process: the view's frames and the
    check cells' draw (an Assistance).

    grey: (F, H, W) uint8 grey frames of the view (what the proposals route tracks on).
    key: the check-cell key (worker.assist.checks.check_key of the instance's signing key).
    assignment_id: the database id of the assignment (the check cells depend on it).
    prefill: the view's pre-fill suggestions, None before worker.assist.prefill's
        MIN_ACCEPTED_VIEWS other views are done.
    follows, retracks: as Assistance (off: the worker of bench/assist.py).
    model: the model follow ((keyframe rows per point, begin) -> (F, P, 2) px, (F, P) ok,
        before the check cells), None: not offered.
    """

    grey: np.ndarray
    key: bytes
    assignment_id: int
    prefill: Prefill | None = None
    follows: bool = False
    retracks: bool = False
    model: Callable[[list[list[list[Any]]], int | None],
                    tuple[np.ndarray, np.ndarray]] | None = None

    @property
    def frames(self) -> int:
        return int(self.grey.shape[0]) if self.grey.ndim == 3 else -1

    @property
    def size(self) -> tuple[int, int]:
        return int(self.grey.shape[2]), int(self.grey.shape[1])

    def proposals(self, anchors: list[list[list[Any]]], forward: list[int]
                  ) -> tuple[np.ndarray, np.ndarray]:
        found = propose(self.grey, anchors)
        xy, ok = found.xy.copy(), found.ok.copy()
        starts = [(int(anchors[p][-1][0]), float(anchors[p][-1][1]),
                   float(anchors[p][-1][2]), True) for p in forward]
        if starts:
            followed = follow(self.grey, starts)
            for i, p in enumerate(forward):
                after = np.arange(self.frames) > starts[i][0]
                held = followed.ok[:, i] & after
                xy[held, p], ok[after, p] = followed.xy[held, i], held[after]
        return self._planted(xy, ok), ok

    def model_follow(self, anchors: list[list[list[Any]]], begin: int | None = None
                     ) -> tuple[np.ndarray, np.ndarray] | None:
        if self.model is None:
            return None
        xy, ok = self.model(anchors, begin)
        return self._planted(xy, ok), ok

    def suggestions(self) -> Prefill | None:
        if self.prefill is None:
            return None
        shown = self._planted(self.prefill.xy, self.prefill.shown())
        return Prefill(xy=shown, visible=self.prefill.visible, known=self.prefill.known)

    def _planted(self, xy: np.ndarray, shown: np.ndarray) -> np.ndarray:
        """(F, P, 2) positions with the assignment's check cells moved off where ``shown``
        (F, P), as the routes plant them."""
        frames, points = shown.shape
        return checks.plant(self.key, self.assignment_id, xy.transpose(1, 0, 2), shown.T, 0,
                            frames, points, self.size[0], self.size[1]).transpose(1, 0, 2)


@dataclass
class Actions:
    """What a worker did for one assignment (see the module docstring for the rule)."""

    clicks: int = 0
    drags: int = 0
    keys: int = 0
    keyframes_placed: int = 0
    requests: int = 0
    writes: int = 0

    def as_dict(self) -> dict[str, int]:
        return {"clicks": self.clicks, "drags": self.drags, "keys": self.keys,
                "keyframes_placed": self.keyframes_placed, "requests": self.requests,
                "writes": self.writes, "edits": self.edits}

    @property
    def total(self) -> int:
        return self.clicks + self.drags + self.keys

    @property
    def edits(self) -> int:
        """What the annotation page's edit counter records (the module docstring)."""
        return self.clicks + self.drags + self.keys - self.requests


@dataclass(frozen=True)
class AssistedWork:
    """One simulated assisted worker's annotation of one view.

    tracks: P lists of keyframe rows, sorted by frame; a 5th element only when not "placed".
    actions: {clicks, drags, keys, keyframes_placed, requests, writes, edits} (Actions).
    seen: (F, P, 2) px, where the worker clicks or drags each point to (truth plus its noise).
    judged: (F, P, 2) px, where it sees each point when it judges a shown marker.
    rounds: proposal requests made.
    """

    profile: str
    tracks: list[list[list[Any]]]
    actions: dict[str, int]
    seen: np.ndarray
    judged: np.ndarray
    rounds: int


@dataclass
class _State:
    """The worker's keyframes while it works: per point {frame: [f, x, y, vis01, source]}."""

    rows: list[dict[int, list[Any]]]
    actions: Actions = field(default_factory=Actions)
    rounds: int = 0

    def anchors(self, point: int) -> list[int]:
        """Frames of the point's keyframes that are not accepted proposals, sorted."""
        return sorted(f for f, r in self.rows[point].items() if r[4] != "tracked")

    def plain(self, point: int) -> list[list[Any]]:
        """The point's keyframes as 4-element rows (what interpolation and LK take)."""
        return [r[:4] for _, r in sorted(self.rows[point].items())]

    def keyed_visible(self, frames: int) -> np.ndarray:
        """(F, P) bool: where a point has a keyframe marked visible."""
        return np.array([[f in rows and bool(rows[f][3]) for rows in self.rows]
                         for f in range(frames)], bool).reshape(frames, len(self.rows))


def _position(xy: np.ndarray) -> list[float]:
    return [round(float(xy[0]), 2), round(float(xy[1]), 2)]


def _seen(truth: np.ndarray, size: tuple[int, int], rng: np.random.Generator,
          sigma: float) -> np.ndarray:
    """(F, P, 2) where a worker sees the points: truth plus Gaussian noise of ``sigma`` px,
    inside the image (the page accepts 0 <= x < width)."""
    width, height = size
    seen = truth + rng.normal(0.0, sigma, truth.shape)
    seen[..., 0] = np.clip(seen[..., 0], 0.0, width - 1.0)
    seen[..., 1] = np.clip(seen[..., 1], 0.0, height - 1.0)
    return seen


def _place(state: _State, point: int, frame: int, seen: np.ndarray, visible: np.ndarray
           ) -> None:
    """A hand-made keyframe at the seen position: a click when visible, a key when not."""
    vis = bool(visible[frame, point])
    if not np.isfinite(seen[frame, point]).all():
        state.rows[point][frame] = [frame, None, None, 0, "placed"]
    else:
        state.rows[point][frame] = [frame, *_position(seen[frame, point]), int(vis), "placed"]
    state.actions.clicks += int(vis)
    state.actions.keys += int(not vis)
    state.actions.keyframes_placed += 1


def _must_frames(visible: np.ndarray, free: np.ndarray, last: bool = True) -> list[int]:
    """Frames one point needs keyed by hand among the ``free`` ones (no keyframe yet): the
    first, the last (unless ``last`` is False: the point is followed there from its last
    keyframe), and each visibility change: the first frame of the new state, and the last
    visible frame before an occlusion (it bounds a span that can be tracked).
    visible, free: (F,) bool."""
    frames = len(visible)
    need = {0, frames - 1} if last else {0}
    for f in np.flatnonzero(visible[1:] != visible[:-1]) + 1:
        need |= {int(f)} | ({int(f) - 1} if visible[f - 1] else set())
    return sorted(f for f in need if free[f])


def _open_spans(state: _State, point: int, frames: int | None = None) -> list[tuple[int, int]]:
    """(k0, k1) between consecutive anchors of a point, both visible with a position, with
    at least one inner frame; with ``frames`` (the point is followed forward) also (k, frames)
    after its last anchor k when that is visible with a position before the clip's last frame
    (the inner frames k+1..frames-1)."""
    anchors = state.anchors(point)
    rows = state.rows[point]

    def held(f: int) -> bool:
        return bool(rows[f][3]) and rows[f][1] is not None

    out = [(a, b) for a, b in itertools.pairwise(anchors) if b - a >= 2 and held(a) and held(b)]
    if frames is not None and anchors and anchors[-1] < frames - 1 and held(anchors[-1]):
        out.append((anchors[-1], frames))
    return out


def _accept(state: _State, point: int, span: tuple[int, int], xy: np.ndarray,
            ok: np.ndarray) -> tuple[bool, bool]:
    """Replace the span's accepted proposals with the new ones; (whether any was taken,
    whether the point's keyframes changed: taken, or older ones removed)."""
    k0, k1 = span
    rows = state.rows[point]
    removed = False
    for f in range(k0 + 1, k1):
        if f in rows and rows[f][4] == "tracked":
            del rows[f]
            removed = True
        if ok[f, point]:
            rows[f] = [f, *_position(xy[f, point]), 1, "tracked"]
    taken = bool(ok[k0 + 1:k1, point].any())
    return taken, taken or removed


def _worst(state: _State, point: int, span: tuple[int, int], judged: np.ndarray,
           tolerance: float) -> int | None:
    """The inner frame of a span whose shown position is furthest beyond tolerance from where
    the worker sees the point (None when all are within)."""
    k0, k1 = span
    shown = dense_track(state.plain(point), judged.shape[0]).xy
    inner = np.arange(k0 + 1, k1)
    err = np.linalg.norm(shown[inner] - judged[inner, point], axis=1)
    err = np.where(np.isfinite(err), err, np.inf)
    if err.size == 0 or err.max() <= tolerance:
        return None
    return int(inner[int(np.argmax(err))])


def _correct(state: _State, point: int, frame: int, seen: np.ndarray) -> None:
    """Move the point to where the worker sees it: a drag of an accepted proposal, else a
    click (a new keyframe where only the interpolation was shown)."""
    rows = state.rows[point]
    if frame in rows and rows[frame][4] == "tracked":
        rows[frame] = [frame, *_position(seen[frame, point]), 1, "edited"]
        state.actions.drags += 1
    else:
        rows[frame] = [frame, *_position(seen[frame, point]), 1, "placed"]
        state.actions.clicks += 1
        state.actions.keyframes_placed += 1


Spans = list[tuple[int, list[tuple[int, int]]]]


def _track(state: _State, setting: Assistance, seen: np.ndarray, judged: np.ndarray,
           tolerance: float | None) -> None:
    """Ask for proposals over every open span, accept them, and (tolerance given: the careful
    worker) correct each span's worst frame and track the halves again, until all hold.
    tolerance None: the blind acceptor, one request, nothing corrected.

    Each round asks once for every span waiting. The first round is the worker's (T, then
    Enter when something holds); later rounds are the re-tracks around the corrections: the
    page's own writes, one per correction that took something (``retracks``), or the worker's
    T and Enter again."""
    points, frames = len(state.rows), setting.frames
    ends = frames if setting.follows else None
    groups: Spans = [(p, s) for p in range(points) if (s := _open_spans(state, p, ends))]
    by_hand = True
    while groups and state.rounds < MAX_ROUNDS:
        asked: dict[int, list[tuple[int, int]]] = {}
        for point, spans in groups:
            asked.setdefault(point, []).extend(spans)
        anchors = [[state.rows[p][f][:4] for f in state.anchors(p)] if p in asked else []
                   for p in range(points)]
        forward = sorted(p for p, spans in asked.items() if any(b >= frames for _, b in spans))
        xy, ok = setting.proposals(anchors, forward)
        state.rounds += 1
        state.actions.keys += int(by_hand)
        state.actions.requests += int(by_hand)
        taken_any = False
        for point, spans in groups:
            changed = False
            for span in spans:
                took, wrote = _accept(state, point, span, xy, ok)
                taken_any, changed = taken_any or took, changed or wrote
            state.actions.writes += int(changed and not by_hand)
        state.actions.keys += int(taken_any and by_hand)
        by_hand = not setting.retracks
        if tolerance is None:
            break
        groups = []
        for point, spans in asked.items():
            for span in spans:
                frame = _worst(state, point, span, judged, tolerance)
                if frame is None:
                    continue
                _correct(state, point, frame, seen)
                halves = [s for s in ((span[0], frame), (frame, span[1])) if s[1] - s[0] >= 2]
                if halves:
                    groups.append((point, halves))


def _key_a_start(state: _State, seen: np.ndarray, visible: np.ndarray) -> bool:
    """Where no frame has MODEL_START_JOINTS visible joints keyed (the hand mostly hidden on
    the clip's first frame), click every visible joint of the first frame that shows that
    many, as the page asks before the model can start; whether it did."""
    keyed = state.keyed_visible(visible.shape[0])
    shown = np.flatnonzero(visible.sum(axis=1) >= MODEL_START_JOINTS)
    if (keyed.sum(axis=1) >= MODEL_START_JOINTS).any() or not len(shown):
        return False
    frame = int(shown[0])
    for p in np.flatnonzero(visible[frame] & ~keyed[frame]):
        _place(state, int(p), frame, seen, visible)
    return True


def _take_model(state: _State, setting: Assistance, seen: np.ndarray, judged: np.ndarray,
                visible: np.ndarray, tolerance: float | None) -> None:
    """Ask for the hand model's follow from the keyframes placed (a key, not an edit) and
    accept it (Enter) where it proposes a point the keyframes have visible; the careful worker
    then drags each accepted position beyond tolerance. The accepted rows bound the tracking
    that follows (LK starts where the model stopped).

    The careful worker steps through the ghosts outward from the frame it keyed whole and
    stops where the hand has come off: the first frame with MODEL_OFF_JOINTS ghosts beyond
    tolerance (Enter takes only the frames it stepped through). Where at most MODEL_FIX_JOINTS
    are off there, it takes that frame too, drags them onto the hand, and asks again from
    that frame (the follow's ``begin``), up to MODEL_ROUNDS times while each round carries the
    hand MODEL_PROGRESS frames further. Where the page says the model has no frame to start
    from, it keys one (_key_a_start) and asks again."""
    points, frames = len(state.rows), setting.frames

    def ask(begin: int | None) -> tuple[np.ndarray, np.ndarray] | None:
        """M pressed: a key and a request, not an edit."""
        found = setting.model_follow([state.plain(p) for p in range(points)], begin)
        if found is not None:
            state.actions.keys += 1
            state.actions.requests += 1
        return found

    begin: int | None = None
    for _ in range(MODEL_ROUNDS if tolerance is not None else 1):
        found = ask(begin)
        if found is None:
            return
        state.rounds += 1
        if begin is None and not found[1].any() and _key_a_start(state, seen, visible):
            found = ask(begin)
            if found is None:
                return
        xy, ok = found
        taken, refix = _model_round(state, xy, ok, judged, tolerance, begin, frames)
        state.actions.keys += int(taken)
        if tolerance is None:
            return
        for p in range(points):
            for f, row in state.rows[p].items():
                if row[4] == "model" and np.hypot(row[1] - judged[f, p, 0],
                                                  row[2] - judged[f, p, 1]) > tolerance:
                    state.rows[p][f] = [f, *_position(seen[f, p]), 1, "edited"]
                    state.actions.drags += 1
        if refix is None or (begin is not None and refix - begin < MODEL_PROGRESS):
            return
        begin = refix


def _model_round(state: _State, xy: np.ndarray, ok: np.ndarray, judged: np.ndarray,
                 tolerance: float | None, begin: int | None, frames: int
                 ) -> tuple[bool, int | None]:
    """Accept one model follow's ghosts (xy (F, P, 2), ok (F, P)) on the frames the worker
    steps through from its start (``begin``, else the first frame keyed whole), as
    _take_model; (whether any was taken, the frame to correct and ask again from, or None)."""
    points = len(state.rows)
    shown_visible = np.stack([dense_track(state.plain(p), frames).visible
                              for p in range(points)], axis=1)
    offered = ok & shown_visible & ~np.array(
        [[f in state.rows[p] for p in range(points)] for f in range(frames)], bool)
    refix = None
    if tolerance is not None and offered.any():
        off = (offered & (np.linalg.norm(xy - judged, axis=-1) > tolerance)).sum(axis=1)
        if begin is None:
            whole = np.flatnonzero(state.keyed_visible(frames).sum(axis=1)
                                   >= MODEL_START_JOINTS)
            start = int(whole[0]) if len(whole) else 0
        else:
            start = begin
        stepped = np.zeros(frames, bool)
        for walk in (range(start, frames), range(start - 1, -1, -1)):
            for f in walk:
                if off[f] >= MODEL_OFF_JOINTS:
                    if walk.step > 0 and off[f] <= MODEL_FIX_JOINTS:
                        stepped[f], refix = True, f
                    break
                stepped[f] = True
        offered &= stepped[:, None]
    taken = False
    for f, p in zip(*np.nonzero(offered), strict=True):
        state.rows[p][int(f)] = [int(f), *_position(xy[f, p]), 1, "model"]
        taken = True
    return taken, refix


def _take_prefill(state: _State, shown: Prefill, seen: np.ndarray, judged: np.ndarray,
                  visible: np.ndarray, tolerance: float | None) -> None:
    """Accept the suggestions as shown (one key, U for every point); the careful worker then
    fixes wrong visibility (a key each) and drags what is beyond tolerance where it sees the
    point."""
    suggested = np.isfinite(shown.xy).all(axis=2)
    for f, p in zip(*np.nonzero(suggested), strict=True):
        state.rows[p][f] = [int(f), *_position(shown.xy[f, p]), int(shown.visible[f, p]),
                            "prefilled"]
    state.actions.keys += int(suggested.any())
    if tolerance is None:
        return
    for f, p in zip(*np.nonzero(suggested), strict=True):
        row = state.rows[p][f]
        if bool(row[3]) != bool(visible[f, p]):
            row[3], row[4] = int(visible[f, p]), "edited"
            state.actions.keys += 1
        off = np.hypot(row[1] - judged[f, p, 0], row[2] - judged[f, p, 1])
        if visible[f, p] and off > tolerance:
            row[1], row[2] = _position(seen[f, p])
            row[4] = "edited"
            state.actions.drags += 1


def _worth_taking(shown: Prefill, judged: np.ndarray, visible: np.ndarray,
                  tolerance: float) -> bool:
    """Whether the careful worker takes the suggestions: at least TAKE_SHARE of those on points
    it sees lie within ``tolerance`` of where it sees them (a glance through the clip shows
    whether the markers sit on the points; suggestions for other spots, or mostly off, are
    more work to drag one by one than to label from the start)."""
    checked = shown.shown() & np.isfinite(shown.xy).all(axis=2) & visible
    if not checked.any():
        return True
    off = np.linalg.norm(shown.xy - judged, axis=2)[checked]
    return bool(np.mean(off <= tolerance) >= TAKE_SHARE)


def assisted_annotate(truth: np.ndarray, visible: np.ndarray, setting: Assistance,
                      profile: str, rng: np.random.Generator,
                      tolerance: float = TOLERANCE_PX,
                      judge_sigma: float = JUDGE_SIGMA_PX) -> AssistedWork:
    """One simulated assisted worker's tracks for one view.

    truth: (F, P, 2) true positions, image px (NaN where unknown); visible: (F, P) bool, the
    true visibility; setting: what the page shows (an Assistance: AssistSetting in process);
    profile: "careful" or "blind"; tolerance, judge_sigma: px, the careful worker's
    (TOLERANCE_PX, JUDGE_SIGMA_PX).
    """
    truth, visible = np.asarray(truth, np.float64), np.asarray(visible, bool)
    frames = setting.frames
    if truth.ndim != 3 or truth.shape[2] != 2 or visible.shape != truth.shape[:2] \
            or truth.shape[0] != frames:
        raise ValueError(f"expected truth (F, P, 2) and visible (F, P) over the view's "
                         f"{frames} frames, got {truth.shape} and {visible.shape}")
    if profile not in ("careful", "blind"):
        raise ValueError(f"unknown assisted profile {profile!r}; one of careful, blind")
    size = setting.size
    seen = _seen(truth, size, rng, CAREFUL_SIGMA_PX)
    judged = _seen(truth, size, rng, judge_sigma)
    state = _State(rows=[{} for _ in range(truth.shape[1])])
    limit = tolerance if profile == "careful" else None
    shown = setting.suggestions()
    if shown is not None and (limit is None or _worth_taking(shown, judged, visible, limit)):
        _take_prefill(state, shown, seen, judged, visible, limit)
    for p in range(truth.shape[1]):
        free = np.array([f not in state.rows[p] for f in range(frames)])
        # The blind acceptor keys the clip's last frame too: tracking between two keyframes
        # fills a whole stretch, a follow from one stops where it loses the point.
        for f in _must_frames(visible[:, p], free,
                              last=not setting.follows or profile == "blind"):
            _place(state, p, f, seen, visible)
    if shown is None:
        _take_model(state, setting, seen, judged, visible, limit)
    _track(state, setting, seen, judged, limit)
    return AssistedWork(profile=profile, tracks=stored_tracks(state.rows),
                        actions=state.actions.as_dict(), seen=seen, judged=judged,
                        rounds=state.rounds)


def stored_tracks(rows: Sequence[dict[int, list[Any]]]) -> list[list[list[Any]]]:
    """Keyframe rows as saved: sorted by frame, the source written only when not "placed" (an
    accepted model follow is saved as tracked, as the page saves every accepted proposal)."""
    return [[r[:4] if r[4] == "placed" else [*r[:4], "tracked"] if r[4] == "model" else r
             for _, r in sorted(point.items())] for point in rows]


def plain_rows(track: Sequence[Sequence[Any]]) -> list[list[Any]]:
    """A track's keyframe rows without their sources ([frame, x, y, visible01])."""
    return [list(r[:4]) for r in track]


def row_source(row: Sequence[Any]) -> str:
    """A keyframe row's source ("placed" for a 4-element row)."""
    return str(row[4]) if len(row) > 4 else "placed"
