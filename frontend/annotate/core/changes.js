/**
 * What an edit of the annotation store (store.js) changes: the keyframe before and after at
 * each (point, frame) it touches, worked out from the entries the store's edits take, and the
 * change description subscribers get once the changes are written.
 *
 * Pure: no DOM; reads the tracks it is given and writes them only in applyWrites.
 */

import { checkIndex, makeKeyframe } from "./keyframe.js";
import { checkSource, sourceAfterEdit, writeTrack } from "./edits.js";

/**
 * @typedef {import("./keyframe.js").Keyframe} Keyframe
 * @typedef {import("./edits.js").KeyframeSource} KeyframeSource
 * @typedef {{frame: number, x?: number|null, y?: number|null, visible?: boolean,
 *   source?: KeyframeSource, remove?: boolean}} FrameEntry  remove: true deletes the keyframe
 * @typedef {{point: number, x?: number|null, y?: number|null, visible?: boolean,
 *   source?: KeyframeSource, remove?: boolean}} PointEntry  remove: true deletes the keyframe
 * @typedef {{point: number|null, frame: number|null, entries: Array<FrameEntry|PointEntry>}}
 *   EntryGroup  point or frame fixed for its entries (null: read entry.point or entry.frame)
 * @typedef {{numFrames: number, width: number, height: number}} Clip  width/height: image px
 * @typedef {{point: number, frame: number, before: Keyframe|null, after: Keyframe|null}} Change
 */

/**
 * The changes that entries {x, y, visible, source?} or {remove: true} make at their point and
 * frame, skipping those that change nothing. Validates everything before anything is written.
 * O(n) in the touched tracks' lengths plus the entries (no search per entry).
 * @param {readonly Keyframe[][]} tracks  one frame-sorted track per point
 * @param {EntryGroup[]} groups
 * @param {Clip} clip
 * @returns {Change[]}
 */
export function changesFor(tracks, groups, clip) {
  const scan = { tracks, clip, byFrame: new Map(), seen: new Set() };
  const changes = [];
  for (const { point: fixedPoint, frame: fixedFrame, entries } of groups) {
    for (const entry of entries) {
      const point = fixedPoint ?? /** @type {PointEntry} */ (entry).point;
      const frame = fixedFrame ?? /** @type {FrameEntry} */ (entry).frame;
      const change = changeAt(point, frame, entry, scan);
      if (change) changes.push(change);
    }
  }
  return changes;
}

/**
 * The change one entry makes at (point, frame), or null when it changes nothing.
 * @param {number} point @param {number} frame @param {FrameEntry|PointEntry} entry
 * @param {{tracks: readonly Keyframe[][], clip: Clip,
 *          byFrame: Map<number, Map<number, Keyframe>>, seen: Set<number>}} scan
 *   byFrame: keyframes by frame of the points seen so far; seen: cells
 *   (point * numFrames + frame) written so far
 * @returns {Change|null}
 */
function changeAt(point, frame, entry, { tracks, clip, byFrame, seen }) {
  checkIndex("point", point, tracks.length);
  checkIndex("frame", frame, clip.numFrames);
  const cell = point * clip.numFrames + frame;
  if (seen.has(cell)) throw new RangeError(`point ${point}, frame ${frame}: given twice`);
  seen.add(cell);
  if (!byFrame.has(point)) {
    byFrame.set(point, new Map(tracks[point].map((k) => [k.frame, k])));
  }
  const before = byFrame.get(point).get(frame) ?? null;
  if (entry.remove === true) return before ? { point, frame, before, after: null } : null;
  const explicit = entry.source !== undefined;
  const source = explicit
    ? checkSource(entry.source, `point ${point}, frame ${frame}`)
    : sourceAfterEdit(before);
  const after = makeKeyframe(frame, /** @type {any} */ (entry), source, clip);
  // Writing a suggestion's own value again, without a source, is no edit of it.
  if (before && samePlace(before, after) && (!explicit || before.source === source)) {
    return null;
  }
  return { point, frame, before, after };
}

/**
 * Same frame, position and visibility (the source aside).
 * @param {Keyframe} a @param {Keyframe} b
 */
function samePlace(a, b) {
  return a.frame === b.frame && a.x === b.x && a.y === b.y && a.visible === b.visible;
}

/**
 * Writes keyframes into the tracks, in place, and describes the change:
 * {label, point, points, created, updated, deleted} (see store.js).
 * @param {Keyframe[][]} tracks
 * @param {string} label
 * @param {Array<[number, number, Keyframe|null, Keyframe|null]>} writes  [point, frame, from, to]
 */
export function applyWrites(tracks, label, writes) {
  /** @type {Map<number, Array<[number, Keyframe|null]>>} */
  const byPoint = new Map();
  const created = new Set();
  const updated = new Set();
  const deleted = new Set();
  for (const [point, frame, from, to] of writes) {
    if (!byPoint.has(point)) byPoint.set(point, []);
    byPoint.get(point).push([frame, to]);
    if (!from && to) created.add(frame);
    else if (from && to) updated.add(frame);
    else if (from && !to) deleted.add(frame);
  }
  for (const [point, pointWrites] of byPoint) writeTrack(tracks[point], pointWrites);
  const points = [...byPoint.keys()].sort((a, b) => a - b);
  const frames = (/** @type {Set<number>} */ set) => [...set].sort((a, b) => a - b);
  return {
    label, point: points.length === 1 ? points[0] : null, points,
    created: frames(created), updated: frames(updated), deleted: frames(deleted),
  };
}
