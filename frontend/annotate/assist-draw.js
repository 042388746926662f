/**
 * The assistance's view: ghosts and epipolar lines on the frame, proposed frames on the
 * timeline, and the assistance buttons, keys and status line of the points panel.
 *
 *   tracking proposal   hollow cyan ring; the active point's path through the held frames as
 *                       thin cyan lines
 *   suggestion          hollow magenta ring (dashed where the other views say occluded)
 *   epipolar line       thin line across the image, one colour per labelled view, tagged with
 *                       the view's camera number ("cam 3"); a legend on the image says what
 *                       they are while any is drawn
 *   where a followed point stopped   an orange bar across its timeline row, on the side of
 *                       the last frame it held at that it did not reach
 *
 * Positions are image px mapped through the editor's Transform; marker sizes are screen px.
 */

import { $ } from "../common/dom.js";
import { Assist } from "./core/assist.js";
import { clipLine } from "./core/epipolar.js";
import { addSceneLayer, traceImagePath } from "./render.js";

export const TRACK_GHOST = "#35d0ff";
export const SUGGEST_GHOST = "#ff5fd2";
export const STOP_MARK = "#ff922b";
const LINE_COLORS = ["#ffe066", "#8ce99a", "#ffa94d", "#b197fc", "#74c0fc"];
/** Ghost ring radius, screen px: outside the point's marker (5 px) and halo (10 px). */
const GHOST_RADIUS_PX = 13;
const OUTLINE = "rgba(0, 0, 0, 0.8)";

/**
 * @typedef {import("./core/transform.js").Transform} Transform
 * @typedef {{ghosts: Array<{point: number, xy: number[]|null, path: number[][][]}>,
 *            suggestion: {point: number, xy: number[], visible: boolean}|null,
 *            lines: import("./core/epipolar.js").EpipolarLine[]}} Layer
 */

/**
 * Draws one frame's assistance. Returns what was drawn (lines with their image-px ends), which
 * the page keeps for tests.
 * @param {CanvasRenderingContext2D} ctx @param {Transform} tf @param {Layer} layer
 * @param {{width: number, height: number, view_serials?: string[]}} image  px; the views'
 *   serials in camera order name each line's view ("cam 3")
 * @param {{width: number, height: number}} canvas  CSS px
 */
export function drawAssistLayer(ctx, tf, layer, image, canvas) {
  const lines = [];
  layer.lines.forEach((line, i) => {
    const ends = clipLine(line, image.width, image.height);
    if (!ends) return;
    const color = LINE_COLORS[i % LINE_COLORS.length];
    const camera = cameraNumber(image.view_serials, line.serial);
    drawEpipolar(ctx, tf, ends, canvas, camera ? `cam ${camera}` : line.serial.slice(-4), color);
    lines.push({ ...line, ends, color, camera });
  });
  for (const g of layer.ghosts) for (const run of g.path) drawPath(ctx, tf, run);
  for (const g of layer.ghosts) if (g.xy) drawRing(ctx, tf, g.xy, TRACK_GHOST, false);
  if (layer.suggestion) {
    drawRing(ctx, tf, layer.suggestion.xy, SUGGEST_GHOST, !layer.suggestion.visible);
  }
  return { lines, ghosts: layer.ghosts.filter((g) => g.xy), suggestion: layer.suggestion };
}

/**
 * A view's camera number (1-based, the sequence's camera order), or null when unknown.
 * @param {string[]|undefined} serials @param {string} serial
 */
function cameraNumber(serials, serial) {
  const i = serials ? serials.indexOf(serial) : -1;
  return i >= 0 ? i + 1 : null;
}

/**
 * The legend of the epipolar lines, on the image beside them: one swatch per line and what the
 * lines mean; hidden while none is drawn. Rebuilt only when what it says changes.
 * @param {HTMLElement} legend
 * @param {Array<{color: string, camera: number|null, serial: string}>} lines  as drawn
 * @param {string} pointName  the active point's name
 */
export function showLineLegend(legend, lines, pointName) {
  const names = lines.map((l) => (l.camera ? `camera ${l.camera}` : `view …${l.serial.slice(-4)}`));
  const key = lines.length ? `${pointName}|${names.join()}|${lines.map((l) => l.color)}` : "";
  if (legend.dataset.key === key) return;
  legend.dataset.key = key;
  legend.hidden = !key;
  if (!key) {
    legend.replaceChildren();
    return;
  }
  const swatches = lines.map((l, i) => {
    const item = document.createElement("span");
    item.className = "line-swatch";
    item.style.setProperty("--line-color", l.color);
    item.textContent = names[i];
    return item;
  });
  const text = document.createElement("span");
  text.textContent = `: where ${lines.length === 1 ? "that camera sees" : "those cameras see"} ` +
    `${pointName}. It lies on ${lines.length === 1 ? "the line" : "each line"} here; E hides them.`;
  legend.replaceChildren("Lines ", ...swatches, text);
}

/**
 * One line, tagged where it enters the visible canvas (zoomed in, its image ends may be off
 * screen). @param {CanvasRenderingContext2D} ctx @param {Transform} tf
 * @param {number[][]} ends  image px @param {{width: number, height: number}} canvas  CSS px
 */
function drawEpipolar(ctx, tf, ends, canvas, tag, color) {
  const seen = clipSegment(ends.map(([x, y]) => tf.toScreen(x, y)), canvas.width, canvas.height);
  if (!seen) return;
  const [a, b] = seen;
  ctx.save();
  ctx.globalAlpha = 0.85;
  ctx.lineWidth = 1.25;
  ctx.strokeStyle = color;
  ctx.beginPath();
  ctx.moveTo(a.x, a.y);
  ctx.lineTo(b.x, b.y);
  ctx.stroke();
  // The tag sits a little way in from the end nearer the image's top-left.
  const [from, to] = a.x + a.y <= b.x + b.y ? [a, b] : [b, a];
  const len = Math.hypot(to.x - from.x, to.y - from.y) || 1;
  const at = Math.min(40, len / 2);
  const x = from.x + ((to.x - from.x) * at) / len;
  const y = from.y + ((to.y - from.y) * at) / len;
  ctx.globalAlpha = 1;
  ctx.font = "11px system-ui, sans-serif";
  const w = ctx.measureText(tag).width + 6;
  ctx.fillStyle = "rgba(0, 0, 0, 0.7)";
  ctx.fillRect(x - w / 2, y - 8, w, 15);
  ctx.fillStyle = color;
  ctx.fillText(tag, x - w / 2 + 3, y + 3);
  ctx.restore();
}

/**
 * The part of a screen segment inside [0, w] x [0, h] (Liang-Barsky), or null.
 * @param {Array<{x: number, y: number}>} ends @param {number} w @param {number} h
 */
function clipSegment([p, q], w, h) {
  const dx = q.x - p.x;
  const dy = q.y - p.y;
  let t0 = 0;
  let t1 = 1;
  for (const [den, num] of [[-dx, p.x], [dx, w - p.x], [-dy, p.y], [dy, h - p.y]]) {
    if (den === 0) {
      if (num < 0) return null;
    } else if (den < 0) {
      t0 = Math.max(t0, num / den);
    } else {
      t1 = Math.min(t1, num / den);
    }
  }
  if (t0 >= t1) return null;
  return [{ x: p.x + t0 * dx, y: p.y + t0 * dy }, { x: p.x + t1 * dx, y: p.y + t1 * dy }];
}

/** A proposal's path through its span, thin. */
function drawPath(ctx, tf, path) {
  if (path.length < 2) return;
  ctx.save();
  ctx.globalAlpha = 0.7;
  ctx.lineWidth = 1;
  ctx.strokeStyle = TRACK_GHOST;
  traceImagePath(ctx, tf, path);
  ctx.stroke();
  ctx.restore();
}

/** A hollow ring with a dark outline (dashed: suggested occluded). */
function drawRing(ctx, tf, [x, y], color, dashed) {
  const s = tf.toScreen(x, y);
  ctx.save();
  ctx.beginPath();
  ctx.arc(s.x, s.y, GHOST_RADIUS_PX, 0, 2 * Math.PI);
  ctx.lineWidth = 4;
  ctx.strokeStyle = OUTLINE;
  ctx.stroke();
  ctx.setLineDash(dashed ? [3, 3] : []);
  ctx.lineWidth = 2;
  ctx.strokeStyle = color;
  ctx.stroke();
  ctx.restore();
}

/**
 * Proposed frames on the timeline: a cyan bar along the top of each frame's cell; where a
 * followed point stopped, an orange bar across its row at the edge of the last frame held.
 * @param {CanvasRenderingContext2D} ctx
 * @param {{cellCentre: (point: number, frame: number) => {x: number, y: number},
 *          cellWidth: number, rowHeight: number}} timeline
 * @param {Array<{point: number, frames: number[]}>} marks
 * @param {Array<{point: number, frame: number, direction: string}>} [stops]
 */
export function drawTimelineMarks(ctx, timeline, marks, stops = []) {
  ctx.fillStyle = TRACK_GHOST;
  const w = Math.max(1, timeline.cellWidth - 1);
  const h = Math.max(2, Math.floor(timeline.rowHeight / 3));
  for (const { point, frames } of marks) {
    for (const f of frames) {
      const c = timeline.cellCentre(point, f);
      ctx.fillRect(c.x - w / 2, c.y - timeline.rowHeight / 2 + 1, w, h);
    }
  }
  ctx.fillStyle = STOP_MARK;
  const bar = Math.max(2, Math.min(4, Math.floor(timeline.cellWidth / 2)));
  for (const s of stops) {
    const c = timeline.cellCentre(s.point, s.frame);
    const x = s.direction === "forward" ? c.x + timeline.cellWidth / 2 - bar : c.x - w / 2;
    ctx.fillRect(x, c.y - timeline.rowHeight / 2, bar, timeline.rowHeight);
  }
}

/**
 * The assistance key of a keydown, run; false when the key is not one of ours.
 *   T / Shift+T  track the active point here / every point     Enter  accept the frames
 *                (past the last keyframe: forward from it;        viewed  (Esc: discard)
 *                before the first: backward from it)
 *   U / Shift+U  use suggestions for the active point / all     E      epipolar lines
 *   M            follow the hand with the hand model (hand tasks)
 * @param {import("./core/assist.js").Assist} assist @param {KeyboardEvent} e
 */
export function assistKey(assist, e) {
  if (e.ctrlKey || e.metaKey || e.altKey) return false;
  const key = e.key.length === 1 ? e.key.toLowerCase() : e.key;
  switch (key) {
    case "t": assist.track(e.shiftKey); return true;
    case "m":
      if (!assist.handModel) return false;
      assist.followModel();
      return true;
    case "Enter": return assist.accept();
    case "u": assist.useSuggestions(e.shiftKey); return true;
    case "e": assist.toggleLines(); return true;
    default: return false;
  }
}

/**
 * Binds the panel's buttons; returns the function that brings the panel up to date.
 * @param {import("./core/assist.js").Assist} assist
 * @param {() => boolean} editable
 * @returns {() => void}
 */
export function wireAssistPanel(assist, editable) {
  const on = (id, fn) => $(id).addEventListener("click", (e) => {
    fn(e);
    if (e.currentTarget instanceof HTMLElement) e.currentTarget.blur();
  });
  on("assist-track", () => assist.track(false));
  on("assist-track-all", () => assist.track(true));
  on("assist-model", () => assist.followModel());
  on("assist-accept", () => assist.accept());
  on("assist-discard", () => assist.discard());
  on("assist-use", (e) => assist.useSuggestions(e.shiftKey));
  on("assist-lines", () => assist.toggleLines());
  return () => {
    const can = editable();
    $("assist").hidden = !can;
    $("assist-model").hidden = !assist.handModel;
    for (const id of ["assist-track", "assist-track-all", "assist-model"]) {
      /** @type {HTMLButtonElement} */ ($(id)).disabled = !can || assist.status.kind === "busy";
    }
    for (const id of ["assist-accept", "assist-discard"]) {
      /** @type {HTMLButtonElement} */ ($(id)).disabled = !can || !assist.proposals;
    }
    $("assist-use").hidden = assist.suggestions.size === 0;
    $("assist-lines").hidden = assist.epipolar.length === 0;
    $("assist-lines").setAttribute("aria-pressed", String(assist.showLines));
    const status = $("assist-status");
    status.textContent = assist.status.text;
    status.dataset.kind = assist.status.kind;
    $("suggest-note").textContent = assist.suggestNote;
  };
}

/**
 * Starts the assistance of a page: the canvas layer, the timeline marks, the panel and the
 * keys. Writes only while `page` is in edit mode and not locked.
 * @param {any} page  app.js's page object
 * @returns {Assist}
 */
export function startAssist(page) {
  const { editor, timeline, task } = page;
  const editable = () => page.data.mode === "edit" && !editor.readOnly && !page.stopped;
  let updatePanel = () => {};
  const assist = new Assist({
    store: page.store, api: page.api, editable, handModel: task.kind === "hand",
    where: () => ({ frame: editor.frame, active: editor.active }),
    onChange: () => {
      editor.render();
      timeline.redraw();
      updatePanel();
    },
  });
  assist.drawn = { lines: [], ghosts: [], suggestion: null };
  addSceneLayer((ctx, scene) => {
    const layer = assist.layer(editor.frame, editor.active);
    assist.drawn = drawAssistLayer(ctx, scene.transform, layer, task,
      { width: scene.cssWidth, height: scene.cssHeight });
    showLineLegend($("epipolar-legend"), assist.drawn.lines, scene.names[editor.active] || "");
  });
  timeline.onRedraw = (ctx) =>
    drawTimelineMarks(ctx, timeline, assist.timelineMarks(), assist.stopMarks());
  updatePanel = wireAssistPanel(assist, editable);
  // Every frame shown (a step, a jump, each frame of playback) is viewed for the points drawn.
  const drawnPoints = () => [...Array(editor.numPoints).keys()].filter((p) => !editor.hidden.has(p));
  assist.noteViewed(editor.frame, drawnPoints());
  page.refreshHooks.push(() => assist.noteViewed(editor.frame, drawnPoints()));
  page.refreshHooks.push(updatePanel);
  window.addEventListener("keydown", (e) => {
    const t = e.target;
    const typing = t instanceof HTMLElement &&
      (t.isContentEditable || ["INPUT", "TEXTAREA", "SELECT"].includes(t.tagName));
    if (typing || document.querySelector("dialog[open]") || !editable()) return;
    const handled = e.key === "Escape" ? assist.discard() : assistKey(assist, e);
    if (handled) e.preventDefault();
  }, true);
  return assist;
}
