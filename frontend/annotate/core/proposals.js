/**
 * The arithmetic of assisted annotation, on one point's keyframes: which stretches tracking
 * runs over, the store writes that take a tracking proposal or the other views' suggestions,
 * and what a proposal holds.
 *
 * Keyframe sources: "placed" (set by hand; a keyframe without source), "edited" (a
 * suggestion the worker changed), "tracked" and "prefilled" (suggestions taken unchanged).
 * Anchors are the keyframes that are not "tracked": tracking runs between them, and beyond
 * the last anchor (forward) or before the first (backward) it follows the point from that one
 * anchor. Such an open span's far end lies outside the clip: [k, numFrames] forward,
 * [-1, k] backward, so that its inner frames are those it may hold at. Positions are image
 * pixels of this view, frames are clip frame indices. No DOM.
 */

/** Sources of keyframes the worker set by hand, which suggestions never replace. */
export const HAND_SOURCES = ["placed", "edited"];

/**
 * @typedef {{frame: number, x: number|null, y: number|null, visible: boolean,
 *            source?: string}} SourcedKeyframe
 * @typedef {{frame: number, x?: number, y?: number, visible?: boolean, source?: string,
 *            remove?: boolean}} Entry  one write of a store batch
 * @typedef {{point: number, first: number, last: number, spans: number[][],
 *            xy: Array<number[]|null>, ok: boolean[]}} PointProposal
 *   first..last: the frames xy/ok cover (xy[i] is frame first + i); spans: [k0, k1] anchor
 *   pairs whose inner frames the proposal decides
 * @typedef {{point: number, direction: "forward"|"backward", from_frame: number,
 *            reached: number, stopped: string}} FollowStop
 *   where a point followed from one anchor stopped, and why ("lost", "left_image", "end")
 * @typedef {{first_frame: number, last_frame: number, points: Array<{point: number,
 *            xy: Array<number[]|null>, ok: boolean[]}>, stops?: FollowStop[]}} ProposalsAnswer
 *   POST /api/annotate/proposals
 */

/** @param {SourcedKeyframe} k */
export function sourceOf(k) {
  return k.source || "placed";
}

/** @param {SourcedKeyframe} k  a keyframe tracking may start or end at */
function isAnchor(k) {
  return sourceOf(k) !== "tracked";
}

/** @param {SourcedKeyframe} k */
function trackable(k) {
  return k.visible && k.x !== null && k.y !== null;
}

/**
 * The anchor pairs around `frame` (a keyframe, or between two): [[k0, k1]] of the nearest
 * anchors on each side, the span after the frame when it is an anchor itself (the one before
 * at the last anchor). [] when there is no anchor on one side or one of them is occluded.
 * @param {SourcedKeyframe[]} keyframes  sorted by frame @param {number} frame
 * @returns {number[][]}
 */
export function spanAround(keyframes, frame) {
  const anchors = keyframes.filter(isAnchor);
  let i = anchors.findIndex((k) => k.frame > frame);
  if (i < 0) i = anchors.length;
  let before = anchors[i - 1];
  let after = anchors[i];
  if (before && before.frame === frame && !after) {
    after = before;
    before = anchors[i - 2];
  }
  if (!before || !after || !trackable(before) || !trackable(after)) return [];
  return after.frame - before.frame >= 2 ? [[before.frame, after.frame]] : [];
}

/**
 * The open span tracking follows from one anchor when `frame` is not between two: forward
 * from the last anchor when the frame is at or after it, backward from the first when the
 * frame is before it. [] when that anchor is occluded or at the clip's end it would leave.
 * @param {SourcedKeyframe[]} keyframes @param {number} frame @param {number} numFrames
 * @returns {number[][]}
 */
export function openSpanAround(keyframes, frame, numFrames) {
  const anchors = keyframes.filter(isAnchor);
  if (!anchors.length) return [];
  const first = anchors[0];
  const last = anchors[anchors.length - 1];
  if (frame >= last.frame) {
    return trackable(last) && last.frame < numFrames - 1 ? [[last.frame, numFrames]] : [];
  }
  if (frame < first.frame) return trackable(first) && first.frame > 0 ? [[-1, first.frame]] : [];
  return [];
}

/**
 * Both open spans of a track (after its last anchor, before its first), where there is room.
 * @param {SourcedKeyframe[]} keyframes @param {number} numFrames @returns {number[][]}
 */
export function openSpans(keyframes, numFrames) {
  const anchors = keyframes.filter(isAnchor);
  if (!anchors.length) return [];
  const before = openSpanAround(keyframes, anchors[0].frame - 1, numFrames);
  const after = openSpanAround(keyframes, anchors[anchors.length - 1].frame, numFrames);
  return [...before, ...after];
}

/**
 * Every anchor pair of a track worth tracking (both visible, at least 2 frames apart).
 * @param {SourcedKeyframe[]} keyframes @returns {number[][]}
 */
export function allSpans(keyframes) {
  const anchors = keyframes.filter(isAnchor);
  const spans = [];
  for (let i = 1; i < anchors.length; i++) {
    const [a, b] = [anchors[i - 1], anchors[i]];
    if (trackable(a) && trackable(b) && b.frame - a.frame >= 2) spans.push([a.frame, b.frame]);
  }
  return spans;
}

/**
 * The anchors as saved rows [frame, x, y, visible01] (what the proposals route tracks from).
 * @param {SourcedKeyframe[]} keyframes @returns {any[][]}
 */
export function anchorRows(keyframes) {
  return keyframeRows(keyframes.filter(isAnchor));
}

/**
 * Every keyframe as a row, accepted proposals too (the hand model's follow takes all the
 * worker has checked). @param {SourcedKeyframe[]} keyframes @returns {Array<Array<number|null>>}
 */
export function keyframeRows(keyframes) {
  return keyframes.map((k) => [k.frame, k.x, k.y, k.visible ? 1 : 0]);
}

/** Visible keyed joints a frame needs before the hand model can start from it (the server's
 * worker.solver.types.FOLLOW_START_JOINTS). */
export const MODEL_START_JOINTS = 6;

/**
 * Whether a frame before `frame` has MODEL_START_JOINTS visible keyframes: the hand model is
 * then asked again from `frame` forward (a correction), not from the first such frame both
 * ways. @param {Array<{keyframes: Array<Array<number|null>>}>} tracks  rows per point
 * @param {number} frame @returns {boolean}
 */
export function handKeyedBefore(tracks, frame) {
  const counts = new Map();
  for (const { keyframes } of tracks) {
    for (const [f, x, , visible] of keyframes) {
      if (f < frame && visible && x !== null) counts.set(f, (counts.get(f) || 0) + 1);
    }
  }
  return [...counts.values()].some((n) => n >= MODEL_START_JOINTS);
}

/**
 * The store writes that take a proposal: inside each span, a "tracked" keyframe where the
 * proposal holds, and the removal of an older tracked keyframe where it does not. Frames that
 * hold an anchor now (the worker keyed them meanwhile), and those `keep` refuses, are left
 * alone.
 * @param {SourcedKeyframe[]} keyframes  the point's keyframes now
 * @param {PointProposal} proposal @param {(frame: number) => boolean} [keep]
 * @returns {Entry[]}
 */
export function proposalEntries(keyframes, proposal, keep = () => true) {
  const byFrame = new Map(keyframes.map((k) => [k.frame, k]));
  const entries = [];
  for (const [k0, k1] of proposal.spans) {
    for (let f = k0 + 1; f < k1; f++) {
      if (!keep(f)) continue;
      const existing = byFrame.get(f);
      if (existing && isAnchor(existing)) continue;
      const i = f - proposal.first;
      const xy = proposal.ok[i] ? proposal.xy[i] : null;
      if (xy) entries.push({ frame: f, x: xy[0], y: xy[1], visible: true, source: "tracked" });
      else if (existing) entries.push({ frame: f, remove: true });
    }
  }
  return entries;
}

/**
 * How many inner span frames a set of proposals holds at. An open span counts only the frames
 * its point was followed to (past them nothing was asked of the tracker).
 * @param {PointProposal[]} proposals @returns {{tracked: number, total: number}}
 */
export function countTracked(proposals) {
  let tracked = 0;
  let total = 0;
  for (const p of proposals) {
    for (const [k0, k1] of p.spans) {
      const open = k0 < p.first || k1 > p.last;
      for (let f = k0 + 1; f < k1; f++) {
        const held = Boolean(p.ok[f - p.first] && p.xy[f - p.first]);
        total += open && !held ? 0 : 1;
        if (held) tracked += 1;
      }
    }
  }
  return { tracked, total };
}

/** "12 of 14 frames tracked; 2 left to interpolation". @param {{tracked: number, total: number}} c */
export function trackedText({ tracked, total }) {
  const unit = total === 1 ? "frame" : "frames";
  const left = total - tracked;
  return `${tracked} of ${total} ${unit} tracked; ${left} left to interpolation`;
}

/**
 * The anchor pairs a hand-set keyframe at `frame` re-tracks: each side (the nearest anchor
 * before it to it, it to the nearest anchor after it; the open span beyond it where it is the
 * outermost anchor) that holds tracked keyframes.
 * @param {SourcedKeyframe[]} keyframes @param {number} frame @param {number} numFrames
 * @returns {number[][]}
 */
export function retrackSpans(keyframes, frame, numFrames) {
  const here = keyframes.find((k) => k.frame === frame);
  if (!here || !isAnchor(here)) return [];
  const anchors = keyframes.filter(isAnchor);
  const i = anchors.indexOf(here);
  const before = anchors[i - 1] ? anchors[i - 1].frame : -1;
  const after = anchors[i + 1] ? anchors[i + 1].frame : numFrames;
  return [[before, frame], [frame, after]].filter(([a, b]) => keyframes.some(
    (k) => !isAnchor(k) && k.frame > a && k.frame < b));
}

/**
 * The store writes that use one point's suggestions: a "prefilled" keyframe at every frame
 * with a suggested position (occluded where the suggestion says so), except at keyframes the
 * worker set by hand.
 * @param {SourcedKeyframe[]} keyframes
 * @param {{xy: Array<number[]|null>, visible: Array<boolean|null>}} suggestion  per frame
 * @returns {Entry[]}
 */
export function prefillEntries(keyframes, suggestion) {
  const byFrame = new Map(keyframes.map((k) => [k.frame, k]));
  const entries = [];
  suggestion.xy.forEach((xy, f) => {
    const existing = byFrame.get(f);
    if (!xy || (existing && HAND_SOURCES.includes(sourceOf(existing)))) return;
    const visible = suggestion.visible[f] !== false;
    entries.push({ frame: f, x: xy[0], y: xy[1], visible, source: "prefilled" });
  });
  return entries;
}

/**
 * The body of POST /api/annotate/proposals: each point's anchors, the frames that cover every
 * span asked for, and the points to follow beyond their outermost anchor (open spans).
 * @param {Map<number, number[][]>} spans  point -> anchor pairs
 * @param {(point: number) => SourcedKeyframe[]} keyframesOf @param {number} numFrames
 */
export function proposalRequest(spans, keyframesOf, numFrames) {
  const all = [...spans.values()].flat();
  const follow = [];
  for (const [point, pairs] of spans) {
    for (const [a, b] of pairs) {
      if (b >= numFrames) follow.push({ point, direction: "forward" });
      else if (a < 0) follow.push({ point, direction: "backward" });
    }
  }
  const body = {
    tracks: [...spans.keys()].map((point) => ({ point, keyframes: anchorRows(keyframesOf(point)) })),
    first_frame: Math.max(0, Math.min(...all.map((s) => s[0]))),
    last_frame: Math.min(numFrames - 1, Math.max(...all.map((s) => s[1]))),
  };
  return follow.length ? { ...body, follow } : body;
}

/**
 * What Enter takes of one proposal: its held frames the worker has viewed, written as
 * "tracked" keyframes (and, the first time, the removal of older tracked keyframes where it
 * does not hold); `rest` keeps the held frames not viewed yet, still a proposal (null when
 * there are none).
 * @param {SourcedKeyframe[]} keyframes @param {PointProposal & {partial?: boolean}} proposal
 * @param {(frame: number) => boolean} viewed  for this proposal's point
 * @returns {{entries: Entry[], taken: number, skipped: number,
 *            rest: (PointProposal & {partial: boolean})|null}}
 */
export function acceptViewed(keyframes, proposal, viewed) {
  const held = new Set(heldFrames(proposal));
  const keep = (f) => (held.has(f) ? viewed(f) : !proposal.partial);
  const entries = proposalEntries(keyframes, proposal, keep);
  const unseen = [...held].filter((f) => !viewed(f));
  const taken = held.size - unseen.length;
  if (!unseen.length) return { entries, taken, skipped: 0, rest: null };
  const ok = proposal.ok.map((o, i) => o && !viewed(proposal.first + i));
  return { entries, taken, skipped: unseen.length, rest: { ...proposal, ok, partial: true } };
}

const STOP_WORDS = {
  lost: "lost the point",
  left_image: "the point left the image",
  end: "reached the end",
};

/**
 * "tracked to frame 31; stopped: lost the point", for one followed point.
 * @param {FollowStop} stop @param {number} numFrames
 */
export function stopText(stop, numFrames) {
  const edge = stop.direction === "forward" ? numFrames - 1 : 0;
  const why = stop.stopped === "end" && stop.reached === edge
    ? `reached the ${stop.direction === "forward" ? "end" : "start"} of the clip`
    : STOP_WORDS[stop.stopped] || stop.stopped;
  const way = stop.direction === "forward" ? "" : " back";
  return `tracked${way} to frame ${stop.reached}; stopped: ${why}`;
}

/**
 * The answer's proposals of the points asked for, each with the spans it decides.
 * @param {ProposalsAnswer} answer @param {Map<number, number[][]>} spans  point -> anchor pairs
 * @returns {PointProposal[]}
 */
export function proposalsFrom(answer, spans) {
  return answer.points.filter((p) => spans.has(p.point)).map((p) => ({
    point: p.point, first: answer.first_frame, last: answer.last_frame,
    spans: spans.get(p.point), xy: p.xy, ok: p.ok,
  }));
}

/**
 * A proposal's held positions in runs of consecutive frames (image px), for its path.
 * @param {PointProposal} p @returns {number[][][]}
 */
export function heldRuns(p) {
  const runs = [];
  let previous = null;
  for (const f of heldFrames(p)) {
    if (previous === null || f !== previous + 1) runs.push([]);
    runs[runs.length - 1].push(p.xy[f - p.first]);
    previous = f;
  }
  return runs;
}

/**
 * The frames inside a proposal's spans where it holds.
 * @param {PointProposal} p @returns {number[]}
 */
export function heldFrames(p) {
  const frames = [];
  for (const [a, b] of p.spans) {
    for (let f = a + 1; f < b; f++) if (p.ok[f - p.first] && p.xy[f - p.first]) frames.push(f);
  }
  return frames;
}

/**
 * @typedef {{direction: "forward"|"backward", reached: number, stopped: string}} ModelStop
 * @typedef {{available: boolean, start_frame: number|null, first_frame: number,
 *            last_frame: number, points: Array<{point: number, xy: Array<number[]|null>,
 *            ok: boolean[]}>, stops: ModelStop[]}} ModelAnswer
 *   POST /api/annotate/model-follow, once available
 */

/**
 * The hand model's follow as proposals: each point it proposes at some frame, over one open
 * span across the whole clip. Partial from the start: Enter writes only the frames it holds
 * (and the worker viewed), never removes what is at the others.
 * @param {ModelAnswer} answer @param {number} numFrames
 * @returns {Array<PointProposal & {partial: boolean}>}
 */
export function modelProposals(answer, numFrames) {
  return answer.points.filter((p) => p.ok.some((o, i) => o && p.xy[i])).map((p) => ({
    point: p.point, first: answer.first_frame, last: answer.last_frame,
    spans: [[-1, numFrames]], xy: p.xy, ok: p.ok, partial: true,
  }));
}

/**
 * What the status line says of the hand model's follow: the frames it followed, from which
 * keyed frame, where and why it stopped, and how to take it.
 * "The hand model followed frames 0-40 from your keyframes on frame 3; it lost the hand after
 * frame 40 (the depth there no longer fits it). ..."
 * @param {ModelAnswer} answer @param {number} numFrames
 */
export function modelText(answer, numFrames) {
  const start = answer.start_frame ?? 0;
  const reached = (direction) => {
    const s = answer.stops.find((x) => x.direction === direction);
    return s ? s.reached : start;
  };
  const [from, to] = [reached("backward"), reached("forward")];
  const lost = answer.stops.filter((s) => s.stopped !== "end")
    .map((s) => `${s.direction === "forward" ? "after" : "before"} frame ${s.reached}`);
  const clip = from === 0 && to === numFrames - 1 ? " (the whole clip)" : "";
  const why = lost.length
    ? `; it lost the hand ${lost.join(" and ")} (the depth there no longer fits it)` : "";
  return `The hand model followed frames ${from}-${to}${clip} from your keyframes on frame ` +
    `${start}${why}. Cyan rings: step through them from frame ${start}; Enter accepts the ` +
    "frames you have viewed, Esc discards. Drag any ring that is off; where a few come off " +
    "together, accept up to that frame, drag them there and press M again to follow on.";
}
