/**
 * The timeline: one row per point across the clip, showing where the point is placed
 * (interpolated: a pale bar), occluded (hatched), and its keyframes (diamonds; hollow when the
 * keyframe says occluded), with a cursor at the current frame. Clicking a keyframe jumps to it
 * and selects its point; clicking elsewhere in a row seeks there; dragging scrubs.
 *
 * The rows are redrawn only when tracks, the active point or the size change; moving the cursor
 * moves one absolutely positioned element, so a frame step costs no canvas work here.
 */

import { denseTrack } from "./core/interpolate.js";

const HEADER_PX = 14;
const GUTTER_PX = 12;
/** A click this close (CSS px) to a keyframe counts as a click on it. */
const KEYFRAME_SNAP_PX = 7;

/**
 * @typedef {import("./core/interpolate.js").Keyframe} Keyframe
 */

export class Timeline {
  /**
   * @param {HTMLElement} container  an empty element; the timeline fills its width
   * @param {{numFrames: number, colors: string[], rowHeight?: number,
   *          onSeek: (frame: number, point: number|null) => void}} options
   *   onSeek: point is the row clicked, or null while scrubbing
   */
  constructor(container, { numFrames, colors, rowHeight = 8, onSeek }) {
    this.container = container;
    this.numFrames = numFrames;
    this.colors = colors;
    this.rowHeight = rowHeight;
    this.onSeek = onSeek;
    /** @type {Keyframe[][]} */
    this.tracks = colors.map(() => []);
    this.active = 0;
    this.frame = 0;
    this.canvas = document.createElement("canvas");
    this.canvas.className = "timeline-canvas";
    this.cursor = document.createElement("div");
    this.cursor.className = "timeline-cursor";
    container.append(this.canvas, this.cursor);
    this._bindPointer();
    this.resize();
  }

  /** Width of one frame's column, CSS px. */
  get cellWidth() {
    return (this.width - GUTTER_PX) / this.numFrames;
  }

  /** Re-measures the container and redraws. */
  resize() {
    const dpr = window.devicePixelRatio || 1;
    this.width = Math.max(this.container.clientWidth, GUTTER_PX + this.numFrames);
    this.height = HEADER_PX + this.colors.length * this.rowHeight + 2;
    this.canvas.width = Math.round(this.width * dpr);
    this.canvas.height = Math.round(this.height * dpr);
    this.canvas.style.width = `${this.width}px`;
    this.canvas.style.height = `${this.height}px`;
    this.cursor.style.height = `${this.height}px`;
    this._dpr = dpr;
    this.redraw();
    this.setFrame(this.frame);
  }

  /** @param {Keyframe[][]} tracks  one keyframe list per point */
  setTracks(tracks) {
    this.tracks = tracks;
    this.redraw();
  }

  /** @param {number} point */
  setActive(point) {
    if (point === this.active) return;
    this.active = point;
    this.redraw();
  }

  /** Moves the cursor. @param {number} frame */
  setFrame(frame) {
    this.frame = frame;
    const x = GUTTER_PX + (frame + 0.5) * this.cellWidth;
    this.cursor.style.transform = `translateX(${x - 1}px)`;
  }

  redraw() {
    const ctx = this.canvas.getContext("2d");
    ctx.setTransform(this._dpr, 0, 0, this._dpr, 0, 0);
    ctx.clearRect(0, 0, this.width, this.height);
    this._drawHeader(ctx);
    this.tracks.forEach((keyframes, point) => this._drawRow(ctx, point, keyframes));
    if (this.onRedraw) this.onRedraw(ctx);
  }

  _drawHeader(ctx) {
    ctx.fillStyle = "#8a939d";
    ctx.font = "10px system-ui, sans-serif";
    for (let f = 0; f < this.numFrames; f += 10) {
      const x = GUTTER_PX + f * this.cellWidth;
      ctx.fillRect(x, HEADER_PX - 4, 1, 4);
      ctx.fillText(String(f), x + 2, HEADER_PX - 4);
    }
  }

  /** @param {CanvasRenderingContext2D} ctx @param {number} point @param {Keyframe[]} keyframes */
  _drawRow(ctx, point, keyframes) {
    const y = HEADER_PX + point * this.rowHeight;
    const h = this.rowHeight - 2;
    const cw = this.cellWidth;
    ctx.fillStyle = point === this.active ? "rgba(255, 255, 255, 0.16)"
      : "rgba(255, 255, 255, 0.04)";
    ctx.fillRect(0, y, this.width, this.rowHeight - 1);
    ctx.fillStyle = this.colors[point];
    ctx.fillRect(2, y + 1, GUTTER_PX - 5, h - 1);
    const dense = denseTrack(keyframes, this.numFrames);
    dense.forEach((v, f) => {
      if (v.state === "unplaced") return;
      const x = GUTTER_PX + f * cw;
      if (!v.visible) {
        ctx.fillStyle = "rgba(230, 80, 80, 0.55)";
        ctx.fillRect(x, y + 1, cw, h - 1);
        ctx.fillStyle = "rgba(20, 20, 20, 0.6)";
        for (let i = 0; i < cw; i += 4) ctx.fillRect(x + i, y + 1, 1, h - 1);
      } else {
        ctx.globalAlpha = 0.35;
        ctx.fillStyle = this.colors[point];
        ctx.fillRect(x, y + 2, cw, h - 3);
        ctx.globalAlpha = 1;
      }
    });
    for (const k of keyframes) this._drawKeyframe(ctx, point, k, y + h / 2);
  }

  _drawKeyframe(ctx, point, k, cy) {
    const cx = GUTTER_PX + (k.frame + 0.5) * this.cellWidth;
    const r = Math.max(2.5, Math.min(this.rowHeight / 2 - 0.5, this.cellWidth / 2));
    ctx.beginPath();
    ctx.moveTo(cx, cy - r);
    ctx.lineTo(cx + r, cy);
    ctx.lineTo(cx, cy + r);
    ctx.lineTo(cx - r, cy);
    ctx.closePath();
    ctx.lineWidth = 1;
    if (k.visible) {
      ctx.fillStyle = this.colors[point];
      ctx.fill();
      ctx.strokeStyle = "#000000";
    } else {
      ctx.strokeStyle = "#ffffff";
    }
    ctx.stroke();
  }

  /**
   * Centre of one frame's cell in one point's row (CSS px within the canvas).
   * @param {number} point @param {number} frame @returns {{x: number, y: number}}
   */
  cellCentre(point, frame) {
    return { x: GUTTER_PX + (frame + 0.5) * this.cellWidth,
      y: HEADER_PX + (point + 0.5) * this.rowHeight };
  }

  /**
   * Which row and frame a point of the canvas is over.
   * @param {number} x @param {number} y  CSS px within the canvas
   * @returns {{frame: number, point: number|null}}
   */
  locate(x, y) {
    const frame = Math.min(this.numFrames - 1, Math.max(0,
      Math.floor((x - GUTTER_PX) / this.cellWidth)));
    const row = Math.floor((y - HEADER_PX) / this.rowHeight);
    const point = row >= 0 && row < this.tracks.length ? row : null;
    if (point === null) return { frame, point };
    let best = null;
    for (const k of this.tracks[point]) {
      const d = Math.abs(GUTTER_PX + (k.frame + 0.5) * this.cellWidth - x);
      if (d <= KEYFRAME_SNAP_PX && (best === null || d < best.d)) best = { d, frame: k.frame };
    }
    return { frame: best ? best.frame : frame, point };
  }

  _bindPointer() {
    let scrubbing = false;
    const where = (e) => {
      const r = this.canvas.getBoundingClientRect();
      return this.locate(e.clientX - r.left, e.clientY - r.top);
    };
    this.canvas.addEventListener("pointerdown", (e) => {
      if (e.button !== 0) return;
      scrubbing = true;
      this.canvas.setPointerCapture(e.pointerId);
      const { frame, point } = where(e);
      this.onSeek(frame, point);
    });
    this.canvas.addEventListener("pointermove", (e) => {
      if (scrubbing) this.onSeek(where(e).frame, null);
    });
    const stop = () => { scrubbing = false; };
    this.canvas.addEventListener("pointerup", stop);
    this.canvas.addEventListener("pointercancel", stop);
  }
}
