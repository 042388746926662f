/**
 * The annotation store: per point of a task, its keyframes (image pixels, see interpolate.js).
 *
 * Every mutation is a command run through the undo stack, so each edit can be undone and redone.
 * Subscribers get a change description per applied change:
 *   {cause: "edit"|"undo"|"redo"|"saved", label, point, points, created, updated, deleted,
 *    editCount}
 * where points lists the points touched, point is the one touched point (null for "saved" and
 * for an edit of several points, such as setPose or setTracks) and created/updated/deleted list
 * the keyframe frames touched (over all points touched).
 *
 * Every keyframe carries its source (provenance, see edits.js): "placed", "tracked",
 * "prefilled" or "edited". Moving an unchanged suggestion ("tracked"/"prefilled") or changing its
 * visibility makes it "edited" unless the edit names a source; moving a keyframe in time keeps it.
 *
 * Stored positions are rounded to 0.01 px (the precision of the autosave payload, so toJSON and
 * fromJSON round-trip exactly) and clamped into the image, 0 <= x < width, 0 <= y < height
 * (keyframe.js). What an edit changes, and the description of it, is worked out in changes.js.
 */

import { denseTrack, valueAt } from "./interpolate.js";
import { UndoStack } from "./undo.js";
import { KeyframeEdit, indexOfFrame } from "./edits.js";
import { checkIndex, clampToImage, keyframeToRow, trackFromRows } from "./keyframe.js";
import { applyWrites, changesFor } from "./changes.js";

export { KEYFRAME_SOURCES } from "./edits.js";
export { POSITION_STEP_PX } from "./keyframe.js";

/**
 * @typedef {import("./edits.js").KeyframeSource} KeyframeSource
 * @typedef {import("./keyframe.js").Keyframe} Keyframe
 * @typedef {{x: number|null, y: number|null, visible: boolean, source?: KeyframeSource}}
 *   KeyframeValue  without source: see sourceAfterEdit in edits.js
 * @typedef {import("./changes.js").FrameEntry} FrameEntry
 * @typedef {import("./changes.js").PointEntry} PointEntry
 */

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
    /**
     * The worker's own actions (what pay and cost count): each edit the worker makes, a drag
     * once however many steps it takes, each undo and redo; not what the page writes by itself
     * (a re-track after a correction).
     */
    this.actionCount = 0;
    /** The gesture id of the last counted edit: a drag's later steps are the same action. */
    this._countedGesture = undefined;
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
    const track = this._tracks[point];
    const i = indexOfFrame(track, frame);
    return i >= 0 ? track[i] : null;
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
    return clampToImage(x, y, this);
  }

  /**
   * Creates or replaces the keyframe at `frame`. Returns false when nothing changed. Without
   * `value.source`, a new keyframe is "placed" and a changed "tracked"/"prefilled" one "edited".
   * @param {number} point @param {number} frame @param {KeyframeValue} value
   * @param {{gesture?: any}} [options] edits sharing a gesture id merge into one undo step
   */
  setKeyframe(point, frame, value, options = {}) {
    return this.setKeyframes(point, [{ ...value, frame }], { ...options, label: "set keyframe" });
  }

  /**
   * Puts the point at (x, y) image px, visible, at `frame` (creating or updating its keyframe).
   * @param {number} point @param {number} frame @param {number} x @param {number} y
   * @param {{gesture?: any, source?: KeyframeSource}} [options]
   */
  placePoint(point, frame, x, y, options = {}) {
    const { source, ...rest } = options;
    return this.setKeyframe(point, frame, { x, y, visible: true, source }, rest);
  }

  /**
   * Writes many keyframes of one point as ONE undo step with ONE change notification (accepting
   * a tracked span of a long clip). Each entry is {frame, x, y, visible, source?} as in
   * setKeyframe, or {frame, remove: true} to delete the keyframe there. Entries that change
   * nothing are skipped; returns false when none changed anything. Frames must be unique.
   * @param {number} point @param {FrameEntry[]} entries
   * @param {{gesture?: any, label?: string}} [options]
   */
  setKeyframes(point, entries, options = {}) {
    this._checkPoint(point);
    if (!Array.isArray(entries)) throw new TypeError("entries must be an array");
    const changes = changesFor(this._tracks, [{ point, frame: null, entries }], this);
    return this._execute(options.label ?? "set keyframes", changes, options.gesture);
  }

  /**
   * Writes keyframes of several points over several frames as ONE undo step with ONE change
   * notification, whose `points` lists every point touched (accepting "Track all", using every
   * point's suggestions). Each group is {point, entries} with entries as in setKeyframes; points
   * must be unique. Everything is validated before anything is written. Returns false when no
   * entry changed anything. O(n log n) in the entries and the touched tracks' lengths.
   * @param {Array<{point: number, entries: FrameEntry[]}>} entriesByPoint
   * @param {{gesture?: any, label?: string, automatic?: boolean}} [options] automatic: the page
   *   writes it by itself (not a worker's action)
   */
  setTracks(entriesByPoint, options = {}) {
    if (!Array.isArray(entriesByPoint)) throw new TypeError("entriesByPoint must be an array");
    const points = new Set();
    const groups = entriesByPoint.map((group, i) => {
      const { point, entries } = group ?? {};
      this._checkPoint(point);
      if (points.has(point)) throw new RangeError(`point ${point}: given twice`);
      points.add(point);
      if (!Array.isArray(entries)) {
        throw new TypeError(`entriesByPoint[${i}] (point ${point}): entries must be an array`);
      }
      return { point, frame: null, entries };
    });
    const changes = changesFor(this._tracks, groups, this);
    return this._execute(options.label ?? "set tracks", changes, options.gesture,
      options.automatic === true);
  }

  /**
   * Writes several points at one frame as ONE undo step with ONE change notification (copying
   * the previous pose, dragging a whole skeleton or a finger chain). Each entry is
   * {point, x, y, visible, source?} as in setKeyframe, or {point, remove: true}. Points must be
   * unique. Returns false when nothing changed.
   * @param {number} frame @param {PointEntry[]} entries
   * @param {{gesture?: any, label?: string}} [options] a drag passes one gesture id throughout
   */
  setPose(frame, entries, options = {}) {
    this._checkFrame(frame);
    if (!Array.isArray(entries)) throw new TypeError("entries must be an array");
    const changes = changesFor(this._tracks, [{ point: null, frame, entries }], this);
    return this._execute(options.label ?? "set pose", changes, options.gesture);
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
    return this._execute("move keyframe", [
      { point, frame: fromFrame, before: moving, after: null },
      { point, frame: toFrame, before: null, after: moved },
    ]);
  }

  /** @param {number} point @param {number} frame @returns {boolean} false when no keyframe */
  deleteKeyframe(point, frame) {
    this._checkPoint(point);
    this._checkFrame(frame);
    const before = this.keyframeAt(point, frame);
    if (!before) return false;
    return this._execute("delete keyframe", [{ point, frame, before, after: null }]);
  }

  /**
   * Flips visibility at `frame`. At a keyframe, flips it in place; elsewhere, creates a keyframe
   * with the interpolated position and the flipped visibility. Before the first keyframe
   * ("unplaced") it marks the point occluded. Returns false where the point would become visible
   * without a position (it has to be placed instead). A flipped "tracked"/"prefilled" keyframe
   * becomes "edited"; a new one is "placed".
   * @param {number} point @param {number} frame
   */
  toggleVisibility(point, frame) {
    this._checkPoint(point);
    this._checkFrame(frame);
    const current = this.valueAt(point, frame);
    const label = { label: "toggle occluded" };
    if (current.state === "unplaced") {
      return this.setKeyframes(point, [{ frame, x: null, y: null, visible: false }], label);
    }
    const visible = !current.visible;
    if (visible && (current.x === null || current.y === null)) return false;
    return this.setKeyframes(point, [{ frame, x: current.x, y: current.y, visible }], label);
  }

  /** @returns {boolean} false when there is nothing to undo */
  undo() {
    return this._counted(this._notify("undo", this._history.undo()), undefined);
  }

  /** @returns {boolean} false when there is nothing to redo */
  redo() {
    return this._counted(this._notify("redo", this._history.redo()), undefined);
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
    const nothing = { point: null, points: [], created: [], updated: [], deleted: [] };
    this._emit({ cause: "saved", label: "save", ...nothing });
  }

  /**
   * Subscribes to changes. @param {(change: object) => void} fn @returns {() => void} unsubscribe
   */
  subscribe(fn) {
    this._listeners.add(fn);
    return () => this._listeners.delete(fn);
  }

  /**
   * Autosave payload: {version, tracks: [{point, keyframes: [row, ...]}]} where a row is
   * [frame, x, y, visible01] for a "placed" keyframe and [frame, x, y, visible01, source]
   * otherwise (so payloads without suggestions are as before).
   */
  toJSON() {
    return {
      version: this.version,
      tracks: this._tracks.map((keyframes, point) => ({
        point,
        keyframes: keyframes.map(keyframeToRow),
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
      store._tracks[track.point] = trackFromRows(track.point, track.keyframes, store);
    }
    return store;
  }

  // ---- internals --------------------------------------------------------------------------

  /** Runs a new edit through the undo stack; false when `changes` is empty. */
  _execute(label, changes, gesture, automatic = false) {
    if (changes.length === 0) return false;
    const command = new KeyframeEdit(this, label, changes, gesture);
    const done = this._notify("edit", this._history.execute(command));
    return automatic ? done : this._counted(done, gesture);
  }

  /** Counts a worker's action that changed something (a gesture's steps once). */
  _counted(done, gesture) {
    if (done && (gesture === undefined || gesture === null || gesture !== this._countedGesture)) {
      this.actionCount += 1;
    }
    if (done) this._countedGesture = gesture ?? undefined;
    return done;
  }

  /**
   * Writes keyframes; called by commands only.
   * @param {string} label
   * @param {Array<[number, number, Keyframe|null, Keyframe|null]>} writes  [point, frame, from, to]
   * @returns {object} the change description
   */
  _write(label, writes) {
    return applyWrites(this._tracks, label, writes);
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

  /** @param {number} point */
  _checkPoint(point) {
    checkIndex("point", point, this.numPoints);
  }

  /** @param {number} frame */
  _checkFrame(frame) {
    checkIndex("frame", frame, this.numFrames);
  }
}
