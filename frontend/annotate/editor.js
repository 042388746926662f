/**
 * The editor: which frame and point the worker is on, the view (zoom/pan), playback, and the
 * edits the controls ask for. It owns the annotation canvas and draws it synchronously, so a
 * frame step is finished (drawn) when step() returns. Input bindings live in pointer.js and
 * keys.js; everything stored goes through the AnnotationStore (image pixels, undoable).
 */

import {
  chainFrom, copySummary, offObjectLandmarks, onOutline, outlineOf, previousPose,
} from "./core/tools.js";
import { Transform } from "./core/transform.js";
import { pointLabels } from "./instructions.js";
import { drawScene } from "./render.js";

/** Playback speeds offered, frames per second. */
export const PLAY_FPS = [5, 15, 30];

/**
 * A landmark this close (image px) outside the highlighted object's outline still counts as on
 * it: the outline is the convex hull of the projected mesh at its initial pose, and a landmark
 * on a corner sits on the outline itself.
 */
export const OUTLINE_TOLERANCE_PX = 3;

export class Editor {
  /**
   * @param {Object} o
   * @param {HTMLCanvasElement} o.canvas
   * @param {{kind: string, num_frames: number, width: number, height: number,
   *          point_names: string[], point_colors: string[], skeleton: number[][],
   *          highlight: object|null}} o.task
   * @param {import("./core/store.js").AnnotationStore} o.store
   * @param {(what: {frame: number, active: number, tracks: boolean}) => void} o.onUpdate
   *   called after every change of frame, active point or tracks (after drawing)
   * @param {(text: string, kind: "info"|"error") => void} [o.onMessage]  what a tool did, or
   *   why an edit was refused
   */
  constructor({ canvas, task, store, onUpdate, onMessage = () => {} }) {
    this.canvas = canvas;
    this.ctx = canvas.getContext("2d", { alpha: false });
    this.task = task;
    this.store = store;
    this.onUpdate = onUpdate;
    this.onMessage = onMessage;
    this.numFrames = task.num_frames;
    this.numPoints = task.point_names.length;
    this.labels = pointLabels(task);
    this.frame = 0;
    this.active = 0;
    /** Editing is refused (preview, submitted, loading, conflict). */
    this.readOnly = true;
    this.transform = new Transform();
    /** @type {Array<ImageBitmap|undefined>} */
    this.bitmaps = [];
    this.fps = PLAY_FPS[1];
    this._playTimer = null;
    this._cssW = 0;
    this._cssH = 0;
    /** The worker zoomed or panned: a resize keeps the view instead of fitting again. */
    this._userView = false;
    /** Every point's value in the current frame, as last drawn. */
    this.points = [];
    /** View settings (not saved to the server): points not drawn, points not movable. */
    this.hidden = new Set();
    this.locked = new Set();
    /** The object's outline (object tasks), the frame it holds for, and what to call it. */
    this.outline = task.kind === "object" ? outlineOf(task.highlight) : null;
    this.outlineFrame = Number.isInteger(task.highlight?.frame) ? task.highlight.frame : 0;
    this.objectLabel = task.highlight?.label || "object";
    store.subscribe((change) => {
      if (change.cause !== "saved") this._changed(true);
    });
  }

  // ---- view -------------------------------------------------------------------------------

  /** Matches the canvas backing store to its CSS size (call on resize). */
  resize() {
    const rect = this.canvas.getBoundingClientRect();
    const dpr = window.devicePixelRatio || 1;
    this._cssW = Math.max(1, rect.width);
    this._cssH = Math.max(1, rect.height);
    this._dpr = dpr;
    this.canvas.width = Math.round(this._cssW * dpr);
    this.canvas.height = Math.round(this._cssH * dpr);
    if (!this._userView) this.fit();
    this.render();
  }

  /** Fits the whole image into the canvas (and keeps it fitted through resizes). */
  fit() {
    this.transform.fit(this._cssW, this._cssH, this.task.width, this.task.height);
    this._userView = false;
    this.render();
  }

  /** @param {number} sx @param {number} sy @param {number} factor  >1 zooms in */
  zoomAt(sx, sy, factor) {
    this.transform.zoomAt(sx, sy, factor);
    this._userView = true;
    this.render();
  }

  /** @param {number} dx @param {number} dy  screen px */
  panBy(dx, dy) {
    this.transform.panBy(dx, dy);
    this._userView = true;
    this.render();
  }

  /** Every point's value in the current frame. */
  pointsHere() {
    const out = new Array(this.numPoints);
    for (let p = 0; p < this.numPoints; p++) out[p] = this.store.valueAt(p, this.frame);
    return out;
  }

  /** Draws the current frame now; `points` keeps the values drawn. */
  render() {
    this.points = this.pointsHere();
    if (!this._cssW) return;
    drawScene(this.ctx, {
      cssWidth: this._cssW, cssHeight: this._cssH, dpr: this._dpr,
      bitmap: this.bitmaps[this.frame] || null,
      imageWidth: this.task.width, imageHeight: this.task.height,
      transform: this.transform,
      points: this.points.map((v, p) => (this.hidden.has(p) ? undefined : v)),
      colors: this.task.point_colors,
      names: this.labels, skeleton: this.task.skeleton || [],
      active: this.active, highlight: this.task.highlight, locked: this.locked,
    });
  }

  // ---- navigation -------------------------------------------------------------------------

  /** @param {number} frame  clamped into the clip */
  goto(frame) {
    const f = Math.min(this.numFrames - 1, Math.max(0, Math.round(frame)));
    if (f === this.frame) return;
    this.frame = f;
    this._changed(false);
  }

  /** @param {number} delta  frames, may be negative */
  step(delta) {
    this.goto(this.frame + delta);
  }

  /**
   * Jumps to the active point's previous (-1) or next (+1) keyframe.
   * @param {-1|1} direction @returns {boolean} false when there is none
   */
  jumpKeyframe(direction) {
    const frames = this.store.keyframes(this.active).map((k) => k.frame);
    const target = direction > 0
      ? frames.find((f) => f > this.frame)
      : frames.reverse().find((f) => f < this.frame);
    if (target === undefined) return false;
    this.goto(target);
    return true;
  }

  /** @param {number} point */
  select(point) {
    if (point < 0 || point >= this.numPoints || point === this.active) return;
    this.active = point;
    this._changed(false);
  }

  /** Selects the next point in task order (wrapping). */
  nextPoint() {
    this.select((this.active + 1) % this.numPoints);
  }

  // ---- playback ---------------------------------------------------------------------------

  get playing() {
    return this._playTimer !== null;
  }

  /** @param {number} fps  one of PLAY_FPS */
  setFps(fps) {
    this.fps = fps;
    if (this.playing) {
      this.pause();
      this.play();
    }
  }

  play() {
    if (this.playing) return;
    if (this.frame >= this.numFrames - 1) this.goto(0);
    this._playTimer = setInterval(() => {
      if (this.frame >= this.numFrames - 1) this.pause();
      else this.step(1);
    }, 1000 / this.fps);
    this._changed(false);
  }

  pause() {
    if (!this.playing) return;
    clearInterval(this._playTimer);
    this._playTimer = null;
    this._changed(false);
  }

  togglePlay() {
    if (this.playing) this.pause();
    else this.play();
  }

  // ---- edits ------------------------------------------------------------------------------

  /**
   * Places the active point at an image position in this frame (visible). A point placed for
   * the first time hands over to the next point, so a first pass over the joints is one click
   * per joint. Refused (with a message) for a hidden or locked point, and for a landmark off
   * the highlighted object.
   * @param {number} x @param {number} y  image px
   * @returns {boolean} whether anything changed
   */
  placeActive(x, y) {
    if (this.readOnly) return false;
    const refusal = this.refusal(this.active, x, y);
    if (refusal) return this._refuse(refusal);
    const first = this.store.keyframes(this.active).length === 0;
    const changed = this.store.placePoint(this.active, this.frame, x, y);
    if (changed && first) this._advanceToUnplaced();
    return changed;
  }

  /**
   * Why `point` may not be put at (x, y) in this frame, or null when it may (x, y omitted:
   * any edit of it).
   * @param {number} point @param {number} [x] @param {number} [y]  image px
   * @returns {string|null}
   */
  refusal(point, x, y) {
    const name = this.labels[point];
    if (this.hidden.has(point)) return `${name} is hidden; show it (H) to edit it`;
    if (this.locked.has(point)) return `${name} is locked; unlock it in the point list to move it`;
    if (x === undefined || y === undefined || !this.outline) return null;
    if (this.frame !== this.outlineFrame) return null;
    if (onOutline(this.outline, x, y, OUTLINE_TOLERANCE_PX)) return null;
    return `landmark ${point + 1} at frame ${this.frame} is outside the highlighted ` +
      `${this.objectLabel}; place it on the object`;
  }

  /**
   * Landmarks placed off the highlighted object (where its outline holds), as messages.
   * @returns {string[]}
   */
  offObjectProblems() {
    if (!this.outline) return [];
    const off = offObjectLandmarks(this.store.tracks(), this.outline, this.outlineFrame,
      OUTLINE_TOLERANCE_PX);
    return off.map(({ point, frame }) => `landmark ${point + 1} at frame ${frame} is outside ` +
      `the highlighted ${this.objectLabel}`);
  }

  /** @param {string} text @returns {false} */
  _refuse(text) {
    this.onMessage(text, "error");
    return false;
  }

  /** After a first placement: the next unplaced point in order, not hidden or locked, if any. */
  _advanceToUnplaced() {
    for (let i = 1; i < this.numPoints; i++) {
      const p = (this.active + i) % this.numPoints;
      const editable = !this.hidden.has(p) && !this.locked.has(p);
      if (editable && this.store.keyframes(p).length === 0) {
        this.select(p);
        return;
      }
    }
  }

  /**
   * Moves a point to an image position in this frame, keeping its visibility (occlusion is
   * changed only by the explicit toggle). Edits sharing `gesture` are one undo step.
   * @param {number} point @param {number} x @param {number} y @param {any} gesture
   */
  movePoint(point, x, y, gesture) {
    if (this.readOnly) return false;
    const refusal = this.refusal(point, x, y);
    if (refusal) return this._refuse(refusal);
    const visible = this.store.valueAt(point, this.frame).visible;
    return this.store.setKeyframe(point, this.frame, { x, y, visible: visible || false },
      { gesture });
  }

  /**
   * The points a group drag of `point` moves: every point ("skeleton") or the point and the
   * joints after it toward the fingertip ("chain"); locked points and points without a
   * position in this frame stay.
   * @param {number} point @param {"skeleton"|"chain"} kind
   * @returns {Array<{point: number, x: number, y: number, visible: boolean}>} their positions
   *   now (image px), the drag's origin
   */
  groupOf(point, kind) {
    const members = kind === "skeleton"
      ? Array.from({ length: this.numPoints }, (_, p) => p)
      : chainFrom(this.task.skeleton || [], point);
    const out = [];
    for (const p of members) {
      const v = this.store.valueAt(p, this.frame);
      if (this.locked.has(p) || v.x === null || v.y === null) continue;
      out.push({ point: p, x: v.x, y: v.y, visible: Boolean(v.visible) });
    }
    return out;
  }

  /**
   * Shifts a group (from groupOf) by (dx, dy) image px from its origin, writing keyframes at
   * this frame; edits sharing `gesture` are one undo step for the whole group.
   * @param {Array<{point: number, x: number, y: number, visible: boolean}>} origin
   * @param {number} dx @param {number} dy @param {any} gesture
   */
  moveGroup(origin, dx, dy, gesture) {
    if (this.readOnly || origin.length === 0) return false;
    const entries = origin.map((o) => ({ point: o.point, x: o.x + dx, y: o.y + dy,
      visible: o.visible }));
    if (this.outline && this.frame === this.outlineFrame) {
      const off = entries.find((e) => !onOutline(this.outline, e.x, e.y, OUTLINE_TOLERANCE_PX));
      if (off) return this._refuse(this.refusal(off.point, off.x, off.y) || "");
    }
    return this.store.setPose(this.frame, entries, { gesture, label: "move group" });
  }

  /**
   * Copies onto this frame every unlocked point's nearest keyframe before it, as one undo
   * step, and says what it copied.
   * @returns {boolean} whether anything changed
   */
  copyPreviousPose() {
    if (this.readOnly) return false;
    const copied = previousPose(this.store.tracks(), this.frame, (p) => this.locked.has(p));
    const summary = copySummary(copied, this.frame);
    if (copied.length === 0) return this._refuse(summary);
    const entries = copied.map(({ point, x, y, visible }) => ({ point, x, y, visible }));
    const changed = this.store.setPose(this.frame, entries, { label: "copy pose" });
    const locked = this.locked.size > 0 ? ` (${this.locked.size} locked kept)` : "";
    this.onMessage(changed ? `${summary}${locked}` : `${summary}: already the same`, "info");
    return changed;
  }

  /**
   * Hides or shows a point (view setting: a hidden point is not drawn and cannot be clicked).
   * @param {number} point @param {boolean} hidden
   */
  setHidden(point, hidden) {
    if (hidden) this.hidden.add(point);
    else this.hidden.delete(point);
    this._changed(false);
  }

  /**
   * Locks or unlocks a point (view setting: a locked point is drawn but no click, drag, copy
   * or key edits it).
   * @param {number} point @param {boolean} locked
   */
  setLocked(point, locked) {
    if (locked) this.locked.add(point);
    else this.locked.delete(point);
    this._changed(false);
  }

  /** Toggles the active point's occlusion in this frame. */
  toggleOccluded() {
    if (this.readOnly) return false;
    const refusal = this.refusal(this.active);
    if (refusal) return this._refuse(refusal);
    return this.store.toggleVisibility(this.active, this.frame);
  }

  /** Removes the active point's keyframe in this frame. */
  deleteKeyframe() {
    if (this.readOnly) return false;
    const refusal = this.refusal(this.active);
    if (refusal) return this._refuse(refusal);
    return this.store.deleteKeyframe(this.active, this.frame);
  }

  undo() {
    return !this.readOnly && this.store.undo();
  }

  redo() {
    return !this.readOnly && this.store.redo();
  }

  /** @param {boolean} tracks  whether keyframes changed */
  _changed(tracks) {
    this.render();
    this.onUpdate({ frame: this.frame, active: this.active, tracks });
  }
}
