/**
 * The annotation store: per point of a task, its keyframes (image pixels, see interpolate.js).
 *
 * Every mutation is a command run through the undo stack, so each edit can be undone and redone.
 * Subscribers get a change description per applied change:
 *   {cause: "edit"|"undo"|"redo"|"saved", label, point, created, updated, deleted, editCount}
 * where created/updated/deleted list the keyframe frames touched (point is null for "saved").
 *
 * Stored positions are rounded to 0.01 px (the precision of the autosave payload, so toJSON and
 * fromJSON round-trip exactly) and clamped into the image, 0 <= x < width, 0 <= y < height.
 */

import { denseTrack, valueAt } from "./interpolate.js";
import { UndoStack } from "./undo.js";

/** Stored coordinate precision, image px. */
export const POSITION_STEP_PX = 0.01;

/** Rounds to the 0.01 px grid (idempotent: a rounded value rounds to itself). @param {number} v */
function quantize(v) {
  return Math.round(v * 100) / 100;
}

/**
 * @typedef {import("./interpolate.js").Keyframe} Keyframe
 * @typedef {{x: number|null, y: number|null, visible: boolean}} KeyframeValue
 * @typedef {{frame: number, before: Keyframe|null, after: Keyframe|null}} FrameChange
 */

/** One undoable edit of one point's keyframes: for each touched frame, before and after. */
class KeyframeEdit {
  /**
   * @param {AnnotationStore} store
   * @param {string} label
   * @param {number} point
   * @param {FrameChange[]} changes
   * @param {any} gesture  edits with the same non-null gesture on the same point merge
   */
  constructor(store, label, point, changes, gesture) {
    this.store = store;
    this.label = label;
    this.point = point;
    this.changes = changes;
    this.gesture = gesture ?? null;
  }

  apply() {
    const writes = this.changes.map((c) => [c.frame, c.before, c.after]);
    return this.store._write(this.label, this.point, writes);
  }

  revert() {
    const writes = this.changes.map((c) => [c.frame, c.after, c.before]);
    return this.store._write(this.label, this.point, writes);
  }

  /** @param {any} next */
  mergeWith(next) {
    if (!(next instanceof KeyframeEdit) || this.gesture === null) return false;
    if (next.gesture !== this.gesture || next.point !== this.point) return false;
    for (const change of next.changes) {
      const mine = this.changes.find((c) => c.frame === change.frame);
      if (mine) mine.after = change.after;
      else this.changes.push({ ...change });
    }
    return true;
  }
}

export class AnnotationStore {
  /**
   * @param {{numPoints: number, numFrames: number, width: number, height: number,
   *          maxUndo?: number, version?: number}} options  width/height: image size in px
   */
  constructor({ numPoints, numFrames, width, height, maxUndo, version = 0 }) {
    for (const [name, v] of Object.entries({ numPoints, numFrames, width, height })) {
      if (!Number.isInteger(v) || v < 1) {
        throw new RangeError(`${name} must be a positive integer, got ${v}`);
      }
    }
    this.numPoints = numPoints;
    this.numFrames = numFrames;
    this.width = width;
    this.height = height;
    /** Server-side version this state is based on (sent back with autosave). */
    this.version = version;
    /** Number of changes applied so far (edits, undos and redos). */
    this.editCount = 0;
    /** editCount at the last acknowledged save. */
    this.savedEditCount = 0;
    /** @type {Keyframe[][]} sorted by frame */
    this._tracks = Array.from({ length: numPoints }, () => []);
    this._history = new UndoStack(maxUndo);
    /** @type {Set<(change: object) => void>} */
    this._listeners = new Set();
  }

  // ---- reading ----------------------------------------------------------------------------

  /** @param {number} point @returns {readonly Keyframe[]} */
  keyframes(point) {
    this._checkPoint(point);
    return Object.freeze(this._tracks[point].slice());
  }

  /** @returns {Keyframe[][]} one keyframe list per point */
  tracks() {
    return this._tracks.map((t) => t.slice());
  }

  /** @param {number} point @param {number} frame @returns {Keyframe|null} */
  keyframeAt(point, frame) {
    this._checkPoint(point);
    return this._tracks[point].find((k) => k.frame === frame) ?? null;
  }

  /** @param {number} point @param {number} frame */
  valueAt(point, frame) {
    this._checkPoint(point);
    return valueAt(this._tracks[point], frame);
  }

  /** @param {number} point */
  denseTrack(point) {
    this._checkPoint(point);
    return denseTrack(this._tracks[point], this.numFrames);
  }

  /** True when there are changes since the last acknowledged save. */
  get dirty() {
    return this.editCount !== this.savedEditCount;
  }

  get canUndo() {
    return this._history.canUndo;
  }

  get canRedo() {
    return this._history.canRedo;
  }

  // ---- editing ----------------------------------------------------------------------------

  /**
   * Clamps an image position into the image (0 <= x < width) on the stored 0.01 px grid.
   * @param {number} x @param {number} y @returns {{x: number, y: number}}
   */
  clampToImage(x, y) {
    // The largest stored coordinate is size - 0.01, so that x < width holds after rounding.
    const clamp = (v, size) =>
      Math.min(Math.max(quantize(v), 0), quantize(size - POSITION_STEP_PX));
    return { x: clamp(x, this.width), y: clamp(y, this.height) };
  }

  /**
   * Creates or replaces the keyframe at `frame`. Returns false when nothing changed.
   * @param {number} point @param {number} frame @param {KeyframeValue} value
   * @param {{gesture?: any}} [options] edits sharing a gesture id merge into one undo step
   */
  setKeyframe(point, frame, value, options = {}) {
    this._checkPoint(point);
    this._checkFrame(frame);
    const after = this._makeKeyframe(frame, value);
    const before = this.keyframeAt(point, frame);
    if (before && sameKeyframe(before, after)) return false;
    return this._execute("set keyframe", point, [{ frame, before, after }], options.gesture);
  }

  /**
   * Puts the point at (x, y) image px, visible, at `frame` (creating or updating its keyframe).
   * @param {number} point @param {number} frame @param {number} x @param {number} y
   * @param {{gesture?: any}} [options]
   */
  placePoint(point, frame, x, y, options = {}) {
    return this.setKeyframe(point, frame, { x, y, visible: true }, options);
  }

  /**
   * Moves a keyframe to another frame. Returns false when there is no keyframe at `fromFrame`
   * or `toFrame` already has one (a keyframe is never silently overwritten by a move).
   * @param {number} point @param {number} fromFrame @param {number} toFrame
   */
  moveKeyframe(point, fromFrame, toFrame) {
    this._checkPoint(point);
    this._checkFrame(fromFrame);
    this._checkFrame(toFrame);
    const moving = this.keyframeAt(point, fromFrame);
    if (!moving || fromFrame === toFrame || this.keyframeAt(point, toFrame)) return false;
    const moved = Object.freeze({ ...moving, frame: toFrame });
    return this._execute("move keyframe", point, [
      { frame: fromFrame, before: moving, after: null },
      { frame: toFrame, before: null, after: moved },
    ]);
  }

  /** @param {number} point @param {number} frame @returns {boolean} false when no keyframe */
  deleteKeyframe(point, frame) {
    this._checkPoint(point);
    this._checkFrame(frame);
    const before = this.keyframeAt(point, frame);
    if (!before) return false;
    return this._execute("delete keyframe", point, [{ frame, before, after: null }]);
  }

  /**
   * Flips visibility at `frame`. At a keyframe, flips it in place; elsewhere, creates a keyframe
   * with the interpolated position and the flipped visibility. Before the first keyframe
   * ("unplaced") it marks the point occluded. Returns false where the point would become visible
   * without a position (it has to be placed instead).
   * @param {number} point @param {number} frame
   */
  toggleVisibility(point, frame) {
    this._checkPoint(point);
    this._checkFrame(frame);
    const current = this.valueAt(point, frame);
    if (current.state === "unplaced") {
      return this.setKeyframe(point, frame, { x: null, y: null, visible: false });
    }
    const visible = !current.visible;
    if (visible && (current.x === null || current.y === null)) return false;
    return this.setKeyframe(point, frame, { x: current.x, y: current.y, visible });
  }

  /** @returns {boolean} false when there is nothing to undo */
  undo() {
    return this._notify("undo", this._history.undo());
  }

  /** @returns {boolean} false when there is nothing to redo */
  redo() {
    return this._notify("redo", this._history.redo());
  }

  // ---- sync -------------------------------------------------------------------------------

  /**
   * Records a save acknowledged by the server.
   * @param {number} version  the server's new version
   * @param {number} [editCount]  editCount at the time the saved payload was taken
   */
  markSaved(version, editCount = this.editCount) {
    this.version = version;
    this.savedEditCount = editCount;
    const nothing = { point: null, created: [], updated: [], deleted: [] };
    this._emit({ cause: "saved", label: "save", ...nothing });
  }

  /**
   * Subscribes to changes. @param {(change: object) => void} fn @returns {() => void} unsubscribe
   */
  subscribe(fn) {
    this._listeners.add(fn);
    return () => this._listeners.delete(fn);
  }

  /** Autosave payload: {version, tracks: [{point, keyframes: [[frame, x, y, visible01], ...]}]}. */
  toJSON() {
    return {
      version: this.version,
      tracks: this._tracks.map((keyframes, point) => ({
        point,
        keyframes: keyframes.map((k) => [k.frame, k.x, k.y, k.visible ? 1 : 0]),
      })),
    };
  }

  /**
   * A store holding a saved payload (see toJSON), with empty undo history.
   * @param {{version: number, tracks: Array<{point: number, keyframes: any[][]}>}} payload
   * @param {{numPoints: number, numFrames: number, width: number, height: number,
   *          maxUndo?: number}} options
   */
  static fromJSON(payload, options) {
    if (!payload || !Array.isArray(payload.tracks)) {
      throw new TypeError("payload.tracks must be an array");
    }
    const store = new AnnotationStore({ ...options, version: Number(payload.version) || 0 });
    for (const track of payload.tracks) {
      store._checkPoint(track.point);
      if (!Array.isArray(track.keyframes)) {
        throw new TypeError(`point ${track.point}: keyframes must be an array`);
      }
      const keyframes = track.keyframes.map((row) => store._keyframeFromRow(track.point, row));
      keyframes.sort((a, b) => a.frame - b.frame);
      keyframes.forEach((k, i) => {
        if (i > 0 && keyframes[i - 1].frame === k.frame) {
          throw new RangeError(`point ${track.point}: two keyframes at frame ${k.frame}`);
        }
      });
      store._tracks[track.point] = keyframes;
    }
    return store;
  }

  // ---- internals --------------------------------------------------------------------------

  /** @param {number} point @param {any[]} row [frame, x, y, visible01] */
  _keyframeFromRow(point, row) {
    if (!Array.isArray(row) || row.length !== 4) {
      const got = JSON.stringify(row);
      throw new TypeError(`point ${point}: keyframe must be [frame, x, y, visible01], got ${got}`);
    }
    const [frame, x, y, visible] = row;
    this._checkFrame(frame);
    if (visible !== 0 && visible !== 1 && visible !== true && visible !== false) {
      throw new TypeError(`point ${point}, frame ${frame}: visible must be 0 or 1, got ${visible}`);
    }
    return this._makeKeyframe(frame, { x, y, visible: Boolean(visible) });
  }

  /** @param {number} frame @param {KeyframeValue} value @returns {Keyframe} */
  _makeKeyframe(frame, { x, y, visible }) {
    if (typeof visible !== "boolean") {
      throw new TypeError(`visible must be a boolean, got ${visible}`);
    }
    if (x === null && y === null) {
      if (visible) throw new TypeError(`frame ${frame}: a visible keyframe needs a position`);
      return Object.freeze({ frame, x: null, y: null, visible });
    }
    if (!Number.isFinite(x) || !Number.isFinite(y)) {
      const got = `${x}, ${y}`;
      const rule = "x and y must be finite numbers or both null";
      throw new TypeError(`frame ${frame}: ${rule}, got ${got}`);
    }
    return Object.freeze({ frame, ...this.clampToImage(x, y), visible });
  }

  /** Runs a new edit through the undo stack. */
  _execute(label, point, changes, gesture) {
    const command = new KeyframeEdit(this, label, point, changes, gesture);
    return this._notify("edit", this._history.execute(command));
  }

  /**
   * Writes keyframes; called by commands only.
   * @param {string} label @param {number} point
   * @param {Array<[number, Keyframe|null, Keyframe|null]>} writes  [frame, from, to]
   * @returns {object} the change description
   */
  _write(label, point, writes) {
    const track = this._tracks[point];
    const change = { label, point, created: [], updated: [], deleted: [] };
    for (const [frame, from, to] of writes) {
      const i = track.findIndex((k) => k.frame === frame);
      if (i >= 0) track.splice(i, 1);
      if (to) track.push(to);
      if (!from && to) change.created.push(frame);
      else if (from && to) change.updated.push(frame);
      else if (from && !to) change.deleted.push(frame);
    }
    track.sort((a, b) => a.frame - b.frame);
    return change;
  }

  /** @param {string} cause @param {object|undefined} change */
  _notify(cause, change) {
    if (!change) return false;
    this.editCount += 1;
    this._emit({ cause, ...change });
    return true;
  }

  _emit(change) {
    const full = { ...change, editCount: this.editCount };
    for (const fn of [...this._listeners]) fn(full);
  }

  _checkPoint(point) {
    if (!Number.isInteger(point) || point < 0 || point >= this.numPoints) {
      throw new RangeError(`point must be an integer in 0..${this.numPoints - 1}, got ${point}`);
    }
  }

  _checkFrame(frame) {
    if (!Number.isInteger(frame) || frame < 0 || frame >= this.numFrames) {
      throw new RangeError(`frame must be an integer in 0..${this.numFrames - 1}, got ${frame}`);
    }
  }
}

/** @param {Keyframe} a @param {Keyframe} b */
function sameKeyframe(a, b) {
  return a.frame === b.frame && a.x === b.x && a.y === b.y && a.visible === b.visible;
}
