/**
 * What the review panel draws: the frame with the worker's points, the references and the
 * lines between them (canvas), the error heat map (canvas) and the timeline of spans (SVG).
 * Each function draws what it is given and keeps no state.
 */

import { svg } from "../common/dom.js";
import {
  NO_ERROR, errorColour, heatFontPx, pointAt, spanRows, spansOf, viewport,
} from "./core/replay.js";

/** A heat map cell without an error where the worker marked the point occluded. */
export const MARKED_OCCLUDED = "#7d8793";
/** Radius of a drawn point, canvas px. */
const DOT = 4;
/** Height of one timeline row, px. */
const SPAN_ROW = 18;

/** @typedef {ReturnType<typeof viewport>} Viewport */

/**
 * Prepare a canvas for drawing in CSS px; its CSS size.
 * @param {HTMLCanvasElement} canvas
 */
function context(canvas) {
  const width = parseFloat(canvas.style.width) || canvas.width;
  const height = parseFloat(canvas.style.height) || canvas.height;
  const ctx = /** @type {CanvasRenderingContext2D} */ (canvas.getContext("2d"));
  const ratio = canvas.width / width;
  ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
  return { ctx, size: { width, height } };
}

/**
 * One frame of a review: the picture (when loaded), the object's outline, the worker's
 * skeleton, a line from each worker point to its reference coloured by the error, the
 * references, and the worker's points over all of it.
 * @param {HTMLCanvasElement} canvas
 * @param {any} review  GET /api/qc/reports/{id}/review
 * @param {number} frame
 * @param {{zoom: number, cx: number, cy: number}} view
 * @param {HTMLImageElement|undefined} image
 * @returns {boolean}  whether the picture was drawn
 */
export function drawFrame(canvas, review, frame, view, image) {
  const { ctx, size } = context(canvas);
  ctx.fillStyle = "#1d232b";
  ctx.fillRect(0, 0, size.width, size.height);
  const vp = viewport({ width: review.width, height: review.height }, size, view);
  const loaded = Boolean(image && image.complete && image.naturalWidth);
  if (loaded) {
    const [x0, y0] = vp.toCanvas(0, 0);
    ctx.drawImage(/** @type {HTMLImageElement} */ (image), x0, y0, review.width * vp.scale,
      review.height * vp.scale);
  }
  if (review.highlight?.polygon?.length) drawOutline(ctx, vp, review.highlight.polygon);
  const at = review.point_names.map((/** @type {string} */ _, /** @type {number} */ p) =>
    pointAt(review, frame, p));
  drawSkeleton(ctx, vp, at, review.skeleton || []);
  for (const q of at) {
    const ref = q.reference ? vp.toCanvas(...q.reference) : null;
    const own = q.xy ? vp.toCanvas(...q.xy) : null;
    if (ref && own) {
      ctx.strokeStyle = errorColour(q.error);
      ctx.lineWidth = 2.5;
      ctx.beginPath();
      ctx.moveTo(own[0], own[1]);
      ctx.lineTo(ref[0], ref[1]);
      ctx.stroke();
    }
    if (ref) drawReference(ctx, ref, q.referenceShown);
  }
  // The worker's points over every line, in point order.
  for (const [p, q] of at.entries()) {
    if (q.xy) drawWorker(ctx, vp.toCanvas(...q.xy), q.visible, review.point_colours[p] || "#fff");
  }
  return loaded;
}

/**
 * The object's outline at its initial pose, dashed.
 * @param {CanvasRenderingContext2D} ctx @param {Viewport} vp @param {number[][]} polygon  px
 */
function drawOutline(ctx, vp, polygon) {
  ctx.save();
  ctx.setLineDash([6, 4]);
  ctx.strokeStyle = "#ffd33d";
  ctx.lineWidth = 2;
  ctx.beginPath();
  for (const [i, [x, y]] of polygon.entries()) {
    const [cx, cy] = vp.toCanvas(x, y);
    if (i === 0) ctx.moveTo(cx, cy);
    else ctx.lineTo(cx, cy);
  }
  ctx.closePath();
  ctx.stroke();
  ctx.restore();
}

/**
 * The worker's skeleton, faint, between the points it placed.
 * @param {CanvasRenderingContext2D} ctx @param {Viewport} vp
 * @param {ReturnType<typeof pointAt>[]} at  @param {number[][]} bones  point index pairs
 */
function drawSkeleton(ctx, vp, at, bones) {
  ctx.strokeStyle = "rgba(255, 255, 255, 0.35)";
  ctx.lineWidth = 1;
  for (const [a, b] of bones) {
    const p = at[a]?.xy, q = at[b]?.xy;
    if (!p || !q) continue;
    const [x1, y1] = vp.toCanvas(...p), [x2, y2] = vp.toCanvas(...q);
    ctx.beginPath();
    ctx.moveTo(x1, y1);
    ctx.lineTo(x2, y2);
    ctx.stroke();
  }
}

/**
 * A filled dot where the worker calls the point visible, a dashed ring where the worker
 * marked it occluded.
 * @param {CanvasRenderingContext2D} ctx @param {number[]} at @param {boolean} visible
 * @param {string} colour
 */
function drawWorker(ctx, at, visible, colour) {
  ctx.save();
  ctx.beginPath();
  ctx.arc(at[0], at[1], DOT, 0, 2 * Math.PI);
  if (visible) {
    ctx.fillStyle = colour;
    ctx.fill();
    ctx.strokeStyle = "#000";
    ctx.lineWidth = 1;
  } else {
    ctx.setLineDash([2, 2]);
    ctx.strokeStyle = colour;
    ctx.lineWidth = 1.5;
  }
  ctx.stroke();
  ctx.restore();
}

/**
 * A white diamond at the reference; dashed grey where the solve calls an anchored landmark
 * hidden.
 * @param {CanvasRenderingContext2D} ctx @param {number[]} at @param {boolean} shown
 */
function drawReference(ctx, at, shown) {
  const r = DOT + 1;
  ctx.save();
  ctx.beginPath();
  ctx.moveTo(at[0], at[1] - r);
  ctx.lineTo(at[0] + r, at[1]);
  ctx.lineTo(at[0], at[1] + r);
  ctx.lineTo(at[0] - r, at[1]);
  ctx.closePath();
  ctx.lineWidth = 1.5;
  ctx.strokeStyle = shown ? "#fff" : "#aab";
  if (!shown) ctx.setLineDash([2, 2]);
  ctx.stroke();
  ctx.restore();
}

/**
 * The heat map: one cell per point and frame coloured by the error (darker grey where the
 * worker marked the point occluded, light grey where no error was measured); names at the
 * left. The layout is written on the canvas' data attributes (left, top, cell, row).
 * @param {HTMLCanvasElement} canvas
 * @param {any} review
 * @param {ReturnType<typeof import("./core/replay.js").heatLayout>} layout
 */
export function drawHeat(canvas, review, layout) {
  const { ctx, size } = context(canvas);
  ctx.clearRect(0, 0, size.width, size.height);
  const font = heatFontPx(layout.row);
  ctx.font = `${font}px system-ui, sans-serif`;
  ctx.textBaseline = "middle";
  const frames = review.num_frames, points = review.point_names.length;
  for (let p = 0; p < points; p += 1) {
    ctx.fillStyle = "#4a5561";
    ctx.fillText(review.point_names[p], 0, layout.top + (p + 0.5) * layout.row, layout.left - 4);
    for (let f = 0; f < frames; f += 1) {
      const error = review.errors?.[f]?.[p];
      const hidden = !review.track.visible[f]?.[p];
      ctx.fillStyle = error !== null && error !== undefined ? errorColour(error)
        : hidden ? MARKED_OCCLUDED : NO_ERROR;
      ctx.fillRect(layout.left + f * layout.cell, layout.top + p * layout.row,
        Math.max(layout.cell - 0.5, 0.5), layout.row - 0.5);
    }
  }
  Object.assign(canvas.dataset, { left: layout.left, top: layout.top,
    cell: layout.cell.toFixed(3), row: layout.row, font });
}

/**
 * The timeline: a cursor, a ruler of frames and a bar per swap or issue span under the heat
 * map's columns (each bar's group carries data-kind, data-first, data-last).
 * @param {SVGSVGElement} timeline
 * @param {any} review
 * @param {ReturnType<typeof import("./core/replay.js").heatLayout>} layout
 * @param {number} width  CSS px
 */
export function drawTimeline(timeline, review, layout, width) {
  const spans = spansOf(review.swaps, review.issues, review.point_names);
  const rows = spanRows(spans);
  const height = 16 + SPAN_ROW * Math.max(Math.max(-1, ...rows) + 1, 1);
  timeline.setAttribute("viewBox", `0 0 ${width} ${height}`);
  timeline.setAttribute("width", String(width));
  timeline.setAttribute("height", String(height));
  const x = (/** @type {number} */ f) => layout.left + f * layout.cell;
  const nodes = [svg("rect", { class: "cursor", x: x(0), y: 0, width: layout.cell, height })];
  const ticks = Math.max(1, Math.ceil(review.num_frames / 12));
  for (let f = 0; f < review.num_frames; f += ticks) {
    nodes.push(svg("text", { x: x(f) + 1, y: 11, class: "tick" }, [String(f)]));
  }
  spans.forEach((s, i) => {
    const y = 16 + rows[i] * SPAN_ROW;
    const w = x(s.frames[1] + 1) - x(s.frames[0]);
    nodes.push(svg("g", { class: `span ${s.kind}`, "data-kind": s.kind,
      "data-first": s.frames[0], "data-last": s.frames[1] }, [
      svg("title", {}, [s.detail]),
      svg("rect", { x: x(s.frames[0]), y, width: Math.max(w, 2), height: SPAN_ROW - 3, rx: 3 }),
      svg("text", { x: x(s.frames[0]) + 3, y: y + SPAN_ROW / 2 + 2 }, [s.label]),
    ]));
  });
  if (!spans.length) {
    nodes.push(svg("text", { x: layout.left, y: 28, class: "none" },
      ["no swaps or issue spans found"]));
  }
  timeline.replaceChildren(...nodes);
}

/**
 * Move the timeline's cursor to a frame.
 * @param {SVGSVGElement} timeline @param {ReturnType<typeof import("./core/replay.js").heatLayout>} layout
 * @param {number} frame
 */
export function moveCursor(timeline, layout, frame) {
  const cursor = timeline.querySelector(".cursor");
  if (!cursor) return;
  cursor.setAttribute("x", String(layout.left + frame * layout.cell));
  cursor.setAttribute("width", String(Math.max(layout.cell, 2)));
}
