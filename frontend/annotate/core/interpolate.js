/**
 * Track interpolation, completeness and plausibility checks for the annotation page.
 *
 * A track is one point (a hand joint or an object landmark) through a clip, stored as keyframes
 * sorted by frame. Positions are image pixels (x right, y down). worker/tracks/ implements the
 * same rules for export and QC; both are checked against tests/fixtures/interpolation_golden.json,
 * so any change here must be made there too.
 *
 * Pure functions: no DOM, no state.
 */

/**
 * @typedef {Object} Keyframe
 * @property {number} frame       frame index in the clip
 * @property {number|null} x      image pixels, or null for an occluded keyframe without a guess
 * @property {number|null} y      image pixels, or null
 * @property {boolean} visible    false = occluded from this frame until the next keyframe
 */

/**
 * @typedef {"keyframe"|"interpolated"|"unplaced"} TrackState
 * @typedef {Object} DenseValue
 * @property {number|null} x
 * @property {number|null} y
 * @property {boolean} visible
 * @property {TrackState} state
 */

/**
 * @typedef {Object} Problem
 * @property {number} point               point index in the task
 * @property {Array<[number, number]>} frames  inclusive frame spans
 * @property {string} message
 */

/**
 * @typedef {Object} Warning
 * @property {"collapsed"|"static"} kind
 * @property {Array<[number, number]>} frames  inclusive frame spans
 * @property {string} message
 */

/** Radius (image px) within which all visible points of a frame count as one spot. */
export const COLLAPSE_RADIUS_PX = 3;
/** Below this largest displacement (image px) over the clip, no point counts as moving. */
export const STATIC_DISPLACEMENT_PX = 1;
/** A frame is "collapsed" only with at least this many visible points (fewer for 2-point tasks). */
export const COLLAPSE_MIN_POINTS = 3;

const UNPLACED = Object.freeze({ x: null, y: null, visible: false, state: "unplaced" });

/** @param {Keyframe} kf */
function hasPosition(kf) {
  return kf.x !== null && kf.x !== undefined && kf.y !== null && kf.y !== undefined;
}

/**
 * Index of the last keyframe whose frame is <= `frame`, or -1.
 * @param {Keyframe[]} keyframes sorted by frame
 * @param {number} frame
 */
function lastAtOrBefore(keyframes, frame) {
  let lo = 0;
  let hi = keyframes.length - 1;
  let found = -1;
  while (lo <= hi) {
    const mid = (lo + hi) >> 1;
    if (keyframes[mid].frame <= frame) {
      found = mid;
      lo = mid + 1;
    } else {
      hi = mid - 1;
    }
  }
  return found;
}

/**
 * Dense value between (or after) keyframes, per the track contract.
 * @param {Keyframe} k0  the keyframe before `frame`
 * @param {Keyframe|undefined} k1  the keyframe after `frame`, if any
 * @param {number} frame
 * @returns {DenseValue}
 */
function between(k0, k1, frame) {
  const visible = Boolean(k0.visible);
  if (!hasPosition(k0)) return { x: null, y: null, visible, state: "interpolated" };
  if (k1 === undefined || !hasPosition(k1)) {
    return { x: k0.x, y: k0.y, visible, state: "interpolated" };
  }
  // The exact formula (and operation order) is shared with worker/tracks/interpolate.py so that
  // both give bit-identical results on the golden vectors.
  const t = (frame - k0.frame) / (k1.frame - k0.frame);
  return {
    x: k0.x + (k1.x - k0.x) * t,
    y: k0.y + (k1.y - k0.y) * t,
    visible,
    state: "interpolated",
  };
}

/**
 * Value of a track at one frame.
 * @param {Keyframe[]} keyframes sorted by frame, frames unique
 * @param {number} frame
 * @returns {DenseValue}
 */
export function valueAt(keyframes, frame) {
  const i = lastAtOrBefore(keyframes, frame);
  if (i < 0) return { ...UNPLACED };
  const k0 = keyframes[i];
  if (k0.frame === frame) {
    return { x: hasPosition(k0) ? k0.x : null, y: hasPosition(k0) ? k0.y : null,
      visible: Boolean(k0.visible), state: "keyframe" };
  }
  return between(k0, keyframes[i + 1], frame);
}

/**
 * Value of a track at every frame of the clip.
 * @param {Keyframe[]} keyframes sorted by frame, frames unique
 * @param {number} numFrames F, the clip length
 * @returns {DenseValue[]} F values
 */
export function denseTrack(keyframes, numFrames) {
  const out = new Array(numFrames);
  for (let f = 0; f < numFrames; f++) out[f] = valueAt(keyframes, f);
  return out;
}

/**
 * Inclusive [start, end] spans of the frames where `flags` is true.
 * @param {boolean[]} flags
 * @returns {Array<[number, number]>}
 */
export function frameSpans(flags) {
  /** @type {Array<[number, number]>} */
  const spans = [];
  for (let f = 0; f < flags.length; f++) {
    if (!flags[f]) continue;
    const last = spans[spans.length - 1];
    if (last && last[1] === f - 1) last[1] = f;
    else spans.push([f, f]);
  }
  return spans;
}

/**
 * "frame 5" or "frames 0-11, 20".
 * @param {Array<[number, number]>} spans
 */
export function formatSpans(spans) {
  const single = spans.length === 1 && spans[0][0] === spans[0][1];
  const text = spans.map(([a, b]) => (a === b ? `${a}` : `${a}-${b}`)).join(", ");
  return `${single ? "frame" : "frames"} ${text}`;
}

/**
 * @param {string[]|null|undefined} pointNames
 * @param {number} index
 */
function pointName(pointNames, index) {
  return pointNames && pointNames[index] !== undefined ? pointNames[index] : `point ${index}`;
}

/**
 * Whether a task's tracks are ready to submit: every point has a keyframe, and every frame of
 * every point is either placed (a position, not "unplaced") or occluded.
 * @param {Keyframe[][]} tracks one keyframe list per point
 * @param {number} numFrames
 * @param {string[]} [pointNames] the task's point names; its length is the number of points
 * @returns {{complete: boolean, problems: Problem[]}}
 */
export function completeness(tracks, numFrames, pointNames) {
  const numPoints = pointNames ? pointNames.length : tracks.length;
  /** @type {Problem[]} */
  const problems = [];
  for (let p = 0; p < numPoints; p++) {
    const keyframes = tracks[p] || [];
    const name = pointName(pointNames, p);
    if (keyframes.length === 0) {
      const frames = numFrames > 0 ? [[0, numFrames - 1]] : [];
      problems.push({ point: p, frames, message: `${name}: no keyframes` });
      continue;
    }
    const missing = denseTrack(keyframes, numFrames).map(
      (v) => v.state === "unplaced" || (v.visible && (v.x === null || v.y === null)),
    );
    const spans = frameSpans(missing);
    if (spans.length > 0) {
      const message = `${name}: ${formatSpans(spans)} not placed`;
      problems.push({ point: p, frames: spans, message });
    }
  }
  return { complete: problems.length === 0, problems };
}

/**
 * Frames whose visible points all lie within COLLAPSE_RADIUS_PX of their centroid.
 * @param {DenseValue[][]} dense per point, per frame
 * @param {number} numFrames
 * @returns {boolean[]}
 */
function collapsedFrames(dense, numFrames) {
  const minPoints = Math.min(COLLAPSE_MIN_POINTS, dense.length);
  const flags = new Array(numFrames).fill(false);
  if (dense.length < 2) return flags;
  for (let f = 0; f < numFrames; f++) {
    const xy = [];
    for (const track of dense) {
      const v = track[f];
      if (v.visible && v.x !== null && v.y !== null) xy.push([v.x, v.y]);
    }
    if (xy.length < minPoints) continue;
    let cx = 0;
    let cy = 0;
    for (const [x, y] of xy) { cx += x; cy += y; }
    cx /= xy.length;
    cy /= xy.length;
    flags[f] = xy.every(([x, y]) => Math.hypot(x - cx, y - cy) <= COLLAPSE_RADIUS_PX);
  }
  return flags;
}

/**
 * Largest distance (image px) of any placed position of any point from that point's first
 * placed position, or null when nothing is placed.
 * @param {DenseValue[][]} dense
 */
function largestDisplacement(dense) {
  let largest = null;
  for (const track of dense) {
    const placed = track.filter((v) => v.x !== null && v.y !== null);
    if (placed.length === 0) continue;
    const [x0, y0] = [placed[0].x, placed[0].y];
    for (const v of placed) largest = Math.max(largest ?? 0, Math.hypot(v.x - x0, v.y - y0));
  }
  return largest;
}

/**
 * Signs of careless work, to show the worker before submit (warnings, not errors).
 * @param {Keyframe[][]} tracks one keyframe list per point
 * @param {number} numFrames
 * @param {string[]} [pointNames]
 * @returns {Warning[]}
 */
export function suspicious(tracks, numFrames, pointNames) {
  const numPoints = pointNames ? pointNames.length : tracks.length;
  const dense = [];
  for (let p = 0; p < numPoints; p++) dense.push(denseTrack(tracks[p] || [], numFrames));
  /** @type {Warning[]} */
  const warnings = [];
  const spans = frameSpans(collapsedFrames(dense, numFrames));
  if (spans.length > 0) {
    warnings.push({
      kind: "collapsed",
      frames: spans,
      message:
        `all visible points within ${COLLAPSE_RADIUS_PX} px of one spot in ${formatSpans(spans)}`,
    });
  }
  const moved = largestDisplacement(dense);
  if (numFrames > 1 && moved !== null && moved < STATIC_DISPLACEMENT_PX) {
    warnings.push({
      kind: "static",
      frames: [[0, numFrames - 1]],
      message: `no point moves across the clip (all within ${STATIC_DISPLACEMENT_PX} px)`,
    });
  }
  return warnings;
}
