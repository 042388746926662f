/**
 * The timeline: one row per point across the clip, labelled with the point's number and name,
 * showing where the point is placed (interpolated: a pale bar), occluded (red, hatched), and its
 * keyframes, shaped by their source (a keyframe's `source`, "placed" when absent):
 *
 *   placed  diamond     tracked  circle     prefilled  triangle     edited  square
 *
 * each filled in the point's colour, hollow when the keyframe says occluded. A cursor marks the
 * current frame. Clicking a keyframe jumps to it and selects its point; clicking elsewhere in a
 * row seeks there; clicking a row's label selects the point only; dragging scrubs. When the rows
 * do not fit, the container scrolls and keeps the active point's row in view.
 *
 * The rows are redrawn only when tracks, the active point or the size change; moving the cursor
 * moves one absolutely positioned element, so a frame step costs no canvas work here.
 */

import { denseTrack } from "./core/interpolate.js";

const HEADER_PX = 14;
/** Width of the row labels ("19 Little DIP" at 11 px), CSS px. */
const GUTTER_PX = 92;
/** A click this close (CSS px) to a keyframe counts as a click on it. */
const KEYFRAME_SNAP_PX = 7;

/**
 * @typedef {import("./core/interpolate.js").Keyframe} Keyframe
 */

export class Timeline {
  /**
   * @param {HTMLElement} container  an empty element; the timeline fills its width
   * @param {{numFrames: number, colors: string[], labels?: string[], rowHeight?: number,
   *          onSeek: (frame: number, point: number|null) => void}} options
   *   labels: what each row is called (instructions.js pointLabels); onSeek: point is the row clicked, or null
   *   while scrubbing; a click on a row's label seeks to the current frame
   */
  constructor(container, { numFrames, colors, labels = [], rowHeight = 16, onSeek }) {
    this.container = container;
    this.numFrames = numFrames;
    this.colors = colors;
    this.labels = colors.map((_, p) => labels[p] ?? String(p));
    this.rowHeight = rowHeight;
    this.onSeek = onSeek;
    /** @type {Keyframe[][]} */
    this.tracks = colors.map(() => []);
    this.active = 0;
    this.frame = 0;
    /** The frame numbers, kept at the top while the rows scroll under them. */
    this.header = document.createElement("canvas");
    this.header.className = "timeline-header";
    this.canvas = document.createElement("canvas");
    this.canvas.className = "timeline-canvas";
    this.cursor = document.createElement("div");
    this.cursor.className = "timeline-cursor";
    container.append(this.header, this.canvas, this.cursor);
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
    this.header.width = this.canvas.width;
    this.header.height = Math.round(HEADER_PX * dpr);
    this.header.style.width = `${this.width}px`;
    this.header.style.height = `${HEADER_PX}px`;
    this.header.style.marginBottom = `${-HEADER_PX}px`;
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
    this.revealActive();
  }

  /** Scrolls the container (when it scrolls) so that the active point's row is in view. */
  revealActive() {
    const c = this.container;
    const top = HEADER_PX + this.active * this.rowHeight;
    const bottom = top + this.rowHeight + 1;  // scrollTop is whole px; keep the row's edge in
    if (top - HEADER_PX < c.scrollTop) c.scrollTop = Math.max(0, top - HEADER_PX);
    else if (bottom > c.scrollTop + c.clientHeight) c.scrollTop = bottom - c.clientHeight;
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
    this._drawHeader();
    this.tracks.forEach((keyframes, point) => this._drawRow(ctx, point, keyframes));
    if (this.onRedraw) this.onRedraw(ctx);
  }

  _drawHeader() {
    const ctx = this.header.getContext("2d");
    ctx.setTransform(this._dpr, 0, 0, this._dpr, 0, 0);
    ctx.fillStyle = "#1f242a";
    ctx.fillRect(0, 0, this.width, HEADER_PX);
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
    this._drawLabel(ctx, point, y, h);
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

  /** The row's colour swatch and its point's number and name, in the gutter. */
  _drawLabel(ctx, point, y, h) {
    ctx.fillStyle = this.colors[point];
    ctx.fillRect(2, y + 2, 5, h - 2);
    ctx.fillStyle = point === this.active ? "#ffffff" : "#c4ccd4";
    ctx.font = `${point === this.active ? "600 " : ""}11px system-ui, sans-serif`;
    ctx.textBaseline = "middle";
    ctx.fillText(this.labels[point], 10, y + h / 2 + 0.5, GUTTER_PX - 14);
    ctx.textBaseline = "alphabetic";
  }

  _drawKeyframe(ctx, point, k, cy) {
    const cx = GUTTER_PX + (k.frame + 0.5) * this.cellWidth;
    const r = Math.max(3, Math.min(this.rowHeight / 2 - 1, this.cellWidth / 2));
    keyframePath(ctx, k.source || "placed", cx, cy, r);
    ctx.lineWidth = 1;
    if (k.visible) {
      ctx.fillStyle = this.colors[point];
      ctx.fill();
      ctx.strokeStyle = "#000000";
    } else {
      ctx.fillStyle = "#15181c";
      ctx.fill();
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
      const { frame, point } = where(e);
      if (e.clientX - this.canvas.getBoundingClientRect().left < GUTTER_PX) {
        if (point !== null) this.onSeek(this.frame, point);
        return;
      }
      scrubbing = true;
      this.canvas.setPointerCapture(e.pointerId);
      this.onSeek(frame, point);
    });
    this.canvas.addEventListener("pointermove", (e) => {
      if (scrubbing) this.onSeek(where(e).frame, null);
    });
    const stop = () => { scrubbing = false; };
    this.canvas.addEventListener("pointerup", stop);
    this.canvas.addEventListener("pointercancel", stop);
    // The header lies over the top of the rows once they scroll: a press on it seeks only.
    this.header.addEventListener("pointerdown", (e) => {
      if (e.button !== 0) return;
      const x = e.clientX - this.canvas.getBoundingClientRect().left;
      if (x >= GUTTER_PX) this.onSeek(this.locate(x, 0).frame, null);
    });
  }
}

/**
 * Traces a keyframe marker of radius r (CSS px) centred at (cx, cy), shaped by its source.
 * @param {CanvasRenderingContext2D} ctx @param {string} source
 * @param {number} cx @param {number} cy @param {number} r
 */
export function keyframePath(ctx, source, cx, cy, r) {
  ctx.beginPath();
  if (source === "tracked") {
    ctx.arc(cx, cy, r * 0.9, 0, 2 * Math.PI);
  } else if (source === "prefilled") {
    ctx.moveTo(cx, cy - r);
    ctx.lineTo(cx + r, cy + r * 0.8);
    ctx.lineTo(cx - r, cy + r * 0.8);
  } else if (source === "edited") {
    const a = r * 0.7;
    ctx.rect(cx - a, cy - a, 2 * a, 2 * a);
  } else {
    ctx.moveTo(cx, cy - r);
    ctx.lineTo(cx + r, cy);
    ctx.lineTo(cx, cy + r);
    ctx.lineTo(cx - r, cy);
  }
  ctx.closePath();
}
