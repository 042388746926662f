/**
 * The editor: which frame and point the worker is on, the view (zoom/pan), playback, and the
 * edits the controls ask for. It owns the annotation canvas and draws it synchronously, so a
 * frame step is finished (drawn) when step() returns. Input bindings live in pointer.js and
 * keys.js; everything stored goes through the AnnotationStore (image pixels, undoable).
 */

import { Transform } from "./core/transform.js";
import { displayName } from "./instructions.js";
import { drawScene } from "./render.js";

/** Playback speeds offered, frames per second. */
export const PLAY_FPS = [5, 15, 30];

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
   */
  constructor({ canvas, task, store, onUpdate }) {
    this.canvas = canvas;
    this.ctx = canvas.getContext("2d", { alpha: false });
    this.task = task;
    this.store = store;
    this.onUpdate = onUpdate;
    this.numFrames = task.num_frames;
    this.numPoints = task.point_names.length;
    this.labels = task.point_names.map((name, i) => `${i} ${displayName(name)}`);
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
      transform: this.transform, points: this.points, colors: this.task.point_colors,
      names: this.labels, skeleton: this.task.skeleton || [],
      active: this.active, highlight: this.task.highlight,
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
   * per joint.
   * @param {number} x @param {number} y  image px
   * @returns {boolean} whether anything changed
   */
  placeActive(x, y) {
    if (this.readOnly) return false;
    const first = this.store.keyframes(this.active).length === 0;
    const changed = this.store.placePoint(this.active, this.frame, x, y);
    if (changed && first) this._advanceToUnplaced();
    return changed;
  }

  /** After a first placement: the next point (in order) that has no keyframe yet, if any. */
  _advanceToUnplaced() {
    for (let i = 1; i < this.numPoints; i++) {
      const p = (this.active + i) % this.numPoints;
      if (this.store.keyframes(p).length === 0) {
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
    const visible = this.store.valueAt(point, this.frame).visible;
    return this.store.setKeyframe(point, this.frame, { x, y, visible: visible || false },
      { gesture });
  }

  /** Toggles the active point's occlusion in this frame. */
  toggleOccluded() {
    if (this.readOnly) return false;
    return this.store.toggleVisibility(this.active, this.frame);
  }

  /** Removes the active point's keyframe in this frame. */
  deleteKeyframe() {
    if (this.readOnly) return false;
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
