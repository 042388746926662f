/**
 * Keyframe provenance and the undoable edit command of the annotation store (store.js).
 *
 * A keyframe's source says where its position came from:
 *   "placed"     the worker put it there (the default; a 4-element saved row means this)
 *   "tracked"    an accepted tracking proposal, unchanged
 *   "prefilled"  an accepted pre-fill suggestion (other views' consensus), unchanged
 *   "edited"     came from a suggestion and the worker then moved it or changed its visibility
 * worker/tracks/keyframes.py reads the same sources from saved rows [frame, x, y, visible01, source].
 *
 * Pure: no DOM, no state outside the objects.
 */

/** @typedef {"placed"|"tracked"|"prefilled"|"edited"} KeyframeSource */

/** Every keyframe source, in the order error messages list them. */
export const KEYFRAME_SOURCES = Object.freeze(["placed", "tracked", "prefilled", "edited"]);

/** Sources of a suggestion accepted unchanged: editing such a keyframe makes it "edited". */
const SUGGESTED = new Set(["tracked", "prefilled"]);

/**
 * Throws unless `source` is one of KEYFRAME_SOURCES.
 * @param {any} source @param {string} where  e.g. "point 3, frame 12"
 * @returns {KeyframeSource}
 */
export function checkSource(source, where) {
  if (!KEYFRAME_SOURCES.includes(source)) {
    const allowed = KEYFRAME_SOURCES.join(", ");
    const got = JSON.stringify(source);
    throw new TypeError(`${where}: source must be one of ${allowed}, got ${got}`);
  }
  return source;
}

/**
 * Source of a keyframe written over `before` without an explicit source: a new keyframe is the
 * worker's own ("placed"); a changed suggestion becomes "edited"; placed and edited stay so.
 * @param {{source: KeyframeSource}|null} before
 * @returns {KeyframeSource}
 */
export function sourceAfterEdit(before) {
  if (!before) return "placed";
  return SUGGESTED.has(before.source) ? "edited" : before.source;
}

/**
 * Index of the keyframe at `frame` in a frame-sorted list, or -1 (binary search).
 * @param {Array<{frame: number}>} track @param {number} frame
 */
export function indexOfFrame(track, frame) {
  let lo = 0;
  let hi = track.length - 1;
  while (lo <= hi) {
    const mid = (lo + hi) >> 1;
    const f = track[mid].frame;
    if (f === frame) return mid;
    if (f < frame) lo = mid + 1;
    else hi = mid - 1;
  }
  return -1;
}

/** A few writes splice in place; more rebuild the track once (a 2000-frame span: O(n log n)). */
const SPLICE_LIMIT = 8;

/**
 * Writes keyframes into one frame-sorted track, in place.
 * @template {{frame: number}} K
 * @param {K[]} track  sorted by frame
 * @param {Array<[number, K|null]>} writes  [frame, new keyframe or null to delete]; unique frames
 */
export function writeTrack(track, writes) {
  if (writes.length <= SPLICE_LIMIT) {
    for (const [frame, to] of writes) {
      const i = indexOfFrame(track, frame);
      if (i >= 0) track.splice(i, 1);
      if (!to) continue;
      let at = 0;
      while (at < track.length && track[at].frame < frame) at += 1;
      track.splice(at, 0, to);
    }
    return;
  }
  const byFrame = new Map(track.map((k) => [k.frame, k]));
  for (const [frame, to] of writes) {
    if (to) byFrame.set(frame, to);
    else byFrame.delete(frame);
  }
  track.length = 0;
  for (const k of byFrame.values()) track.push(k);
  track.sort((a, b) => a.frame - b.frame);
}

/**
 * @template K
 * @typedef {{point: number, frame: number, before: K|null, after: K|null}} KeyframeChange
 */

/**
 * One undoable edit of keyframes of one or more points: for each touched (point, frame), the
 * keyframe before and after. The store writes them through `store._write(label, writes)`.
 */
export class KeyframeEdit {
  /**
   * @param {{_write: (label: string, writes: Array<[number, number, any, any]>) => object}} store
   * @param {string} label
   * @param {KeyframeChange<any>[]} changes  at most one per (point, frame)
   * @param {any} gesture  edits with the same non-null gesture on the same points merge
   */
  constructor(store, label, changes, gesture) {
    this.store = store;
    this.label = label;
    this.changes = changes;
    this.gesture = gesture ?? null;
    this.pointsKey = [...new Set(changes.map((c) => c.point))].sort((a, b) => a - b).join(",");
    /** @type {Map<string, KeyframeChange<any>>|null} built on the first merge */
    this._byCell = null;
  }

  apply() {
    return this.store._write(this.label, this.changes.map((c) => [c.point, c.frame, c.before,
      c.after]));
  }

  revert() {
    return this.store._write(this.label, this.changes.map((c) => [c.point, c.frame, c.after,
      c.before]));
  }

  /** @param {any} next */
  mergeWith(next) {
    if (!(next instanceof KeyframeEdit) || this.gesture === null) return false;
    if (next.gesture !== this.gesture || next.pointsKey !== this.pointsKey) return false;
    if (!this._byCell) this._byCell = new Map(this.changes.map((c) => [cellKey(c), c]));
    for (const change of next.changes) {
      const mine = this._byCell.get(cellKey(change));
      if (mine) {
        mine.after = change.after;
      } else {
        const copy = { ...change };
        this.changes.push(copy);
        this._byCell.set(cellKey(copy), copy);
      }
    }
    return true;
  }
}

/** @param {{point: number, frame: number}} c */
function cellKey(c) {
  return `${c.point}:${c.frame}`;
}
