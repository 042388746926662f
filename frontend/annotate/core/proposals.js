/**
 * The arithmetic of assisted annotation, on one point's keyframes: which stretches tracking
 * runs over, the store writes that take a tracking proposal or the other views' suggestions,
 * and what a proposal holds.
 *
 * Keyframe sources: "placed" (set by hand; a keyframe without source), "edited" (a
 * suggestion the worker changed), "tracked" and "prefilled" (suggestions taken unchanged).
 * Anchors are the keyframes that are not "tracked": tracking runs between them. Positions are
 * image pixels of this view, frames are clip frame indices. No DOM.
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
 * @typedef {{first_frame: number, last_frame: number, points: Array<{point: number,
 *            xy: Array<number[]|null>, ok: boolean[]}>}} ProposalsAnswer
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
  return keyframes.filter(isAnchor).map((k) => [k.frame, k.x, k.y, k.visible ? 1 : 0]);
}

/**
 * The store writes that take a proposal: inside each span, a "tracked" keyframe where the
 * proposal holds, and the removal of an older tracked keyframe where it does not. Frames that
 * hold an anchor now (the worker keyed them meanwhile) are left alone.
 * @param {SourcedKeyframe[]} keyframes  the point's keyframes now
 * @param {PointProposal} proposal @returns {Entry[]}
 */
export function proposalEntries(keyframes, proposal) {
  const byFrame = new Map(keyframes.map((k) => [k.frame, k]));
  const entries = [];
  for (const [k0, k1] of proposal.spans) {
    for (let f = k0 + 1; f < k1; f++) {
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
 * How many inner span frames a set of proposals holds at.
 * @param {PointProposal[]} proposals @returns {{tracked: number, total: number}}
 */
export function countTracked(proposals) {
  let tracked = 0;
  let total = 0;
  for (const p of proposals) {
    for (const [k0, k1] of p.spans) {
      for (let f = k0 + 1; f < k1; f++) {
        total += 1;
        if (p.ok[f - p.first] && p.xy[f - p.first]) tracked += 1;
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
 * before it to it, it to the nearest anchor after it) that holds tracked keyframes.
 * @param {SourcedKeyframe[]} keyframes @param {number} frame @returns {number[][]}
 */
export function retrackSpans(keyframes, frame) {
  const here = keyframes.find((k) => k.frame === frame);
  if (!here || !isAnchor(here)) return [];
  const anchors = keyframes.filter(isAnchor);
  const i = anchors.indexOf(here);
  const sides = [[anchors[i - 1], here], [here, anchors[i + 1]]];
  return sides
    .filter(([a, b]) => a && b && keyframes.some(
      (k) => !isAnchor(k) && k.frame > a.frame && k.frame < b.frame))
    .map(([a, b]) => [a.frame, b.frame]);
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
 * The body of POST /api/annotate/proposals: each point's anchors, and the frames that cover
 * every span asked for.
 * @param {Map<number, number[][]>} spans  point -> anchor pairs
 * @param {(point: number) => SourcedKeyframe[]} keyframesOf
 */
export function proposalRequest(spans, keyframesOf) {
  const all = [...spans.values()].flat();
  return {
    tracks: [...spans.keys()].map((point) => ({ point, keyframes: anchorRows(keyframesOf(point)) })),
    first_frame: Math.min(...all.map((s) => s[0])),
    last_frame: Math.max(...all.map((s) => s[1])),
  };
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
