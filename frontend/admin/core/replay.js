/**
 * The review replay's pure core: no DOM. Colours for errors, the joint x frame heat map's and
 * the timeline's layout, the spans of swaps and issues, the viewport transform between image
 * pixels and the canvas, and the feedback a rejection starts from.
 *
 * Pixels: image x right, y down, as the API sends them (GET /api/qc/reports/{id}/review).
 */

/** An error at or above this (px) is drawn full red: twice QC's 10 px outlier distance. */
export const ERROR_MAX_PX = 20;
/** Colour of a cell or line without an error (no reference there). */
export const NO_ERROR = "#c9ced4";

/**
 * The error's colour: green at 0 px, through yellow at half ERROR_MAX_PX, to red at it.
 * @param {number|null|undefined} px
 * @returns {string}  a CSS colour
 */
export function errorColour(px) {
  if (px === null || px === undefined || !Number.isFinite(px)) return NO_ERROR;
  const t = Math.min(Math.max(px / ERROR_MAX_PX, 0), 1);
  return `hsl(${Math.round(120 * (1 - t))}, 85%, 42%)`;
}

/** The legend's stops: [px, colour], 0 to ERROR_MAX_PX. */
export function legendStops() {
  return [0, 5, 10, 15, 20].map((px) => /** @type {[number, string]} */ ([px, errorColour(px)]));
}

/**
 * The heat map's type size for its point names, CSS px: 13 px where the rows allow (a hand's
 * 21 names read at 13 px like the page's small print; 9 px type drew them about 6 px tall).
 * @param {number} row  the row height, CSS px
 */
export function heatFontPx(row) {
  return Math.max(9, Math.min(row - 2, 13));
}

/**
 * Where the heat map's cells are: one row per point, one column per frame, after a column of
 * point names. Shared with the timeline, whose frames line up with the cells above.
 * @param {number} frames  F
 * @param {number} points  P
 * @param {number} width  the canvas' CSS width, px
 * @param {{label?: number, row?: number}} [size]
 */
export function heatLayout(frames, points, width, size = {}) {
  const left = size.label ?? 92;
  // 21 hand joints at 15 px a row, tall enough for their names in 13 px type (heatFontPx);
  // an object's two landmarks get taller rows.
  const row = size.row ?? Math.max(15, Math.min(22, Math.floor(320 / Math.max(points, 1))));
  const cell = Math.max((width - left) / Math.max(frames, 1), 1);
  return { left, top: 0, cell, row, width: left + cell * frames, height: row * points };
}

/**
 * The cell under a point of the heat map, or null outside the cells.
 * @param {ReturnType<typeof heatLayout>} layout
 * @param {number} x  @param {number} y  CSS px in the canvas
 * @param {number} frames  @param {number} points
 */
export function cellAt(layout, x, y, frames, points) {
  const frame = Math.floor((x - layout.left) / layout.cell);
  const point = Math.floor((y - layout.top) / layout.row);
  if (x < layout.left || frame < 0 || frame >= frames || point < 0 || point >= points) return null;
  return { frame, point };
}

/**
 * @typedef {{kind: "swap"|"issue", frames: [number, number], label: string, detail: string,
 *            points: number[]}} Span
 */

/** The hand joints of each finger (DexYCB order), as swaps name them. */
export const FINGER_JOINTS = {
  thumb: [1, 2, 3, 4], index: [5, 6, 7, 8], middle: [9, 10, 11, 12],
  ring: [13, 14, 15, 16], little: [17, 18, 19, 20],
};

/** @param {[number, number]} frames */
const frameText = (frames) => (frames[0] === frames[1] ? `frame ${frames[0]}`
  : `frames ${frames[0]}–${frames[1]}`);

/**
 * The timeline's spans: each swap (its fingers, or its points on an object) and each issue
 * (one point far off), in frames, with a short label and a sentence.
 * @param {any[]} swaps  report.swaps
 * @param {any[]} issues  the review's issues
 * @param {string[]} names  point names
 * @returns {Span[]}
 */
export function spansOf(swaps, issues, names) {
  /** @type {Span[]} */
  const spans = [];
  for (const s of swaps || []) {
    if (!Array.isArray(s.frames)) continue;
    const fingers = /** @type {string[]} */ (s.fingers || []);
    const points = fingers.flatMap((f) => FINGER_JOINTS[
      /** @type {keyof typeof FINGER_JOINTS} */ (f)] || []);
    const what = fingers.length ? fingers.join(" ↔ ")
      : (s.points || []).map((/** @type {number} */ p) => names[p] ?? `point ${p}`).join(" ↔ ");
    spans.push({ kind: "swap", frames: [s.frames[0], s.frames[1]], points,
      label: `${s.kind === "mirror" ? "mirror" : "swap"} ${what}`,
      detail: s.message ? String(s.message).replace(/\.$/, "")
        : `${what} exchanged in ${frameText(s.frames)}` });
  }
  for (const i of issues || []) {
    if (!Array.isArray(i.frames)) continue;
    const name = (names[i.point] ?? `point ${i.point}`).replace(/_/g, " ");
    const px = i.error_px === null || i.error_px === undefined ? "" : ` ${Number(i.error_px).toFixed(0)} px`;
    const about = i.about && i.about !== "error" ? ` ${i.about}` : "";
    spans.push({ kind: "issue", frames: [i.frames[0], i.frames[1]], points: [i.point],
      label: `${name}${about}${px}`,
      detail: `${name} off by${px || " too much"} in ${frameText(i.frames)}` +
        (i.about && i.about !== "error" ? ` (${i.about})` : "") });
  }
  return spans;
}

/**
 * Rows of the timeline: spans that overlap go on separate rows (first fit, in order).
 * @param {Span[]} spans
 * @returns {number[]}  each span's row
 */
export function spanRows(spans) {
  /** @type {number[]} */ const ends = [];
  return spans.map((s) => {
    let row = ends.findIndex((end) => end < s.frames[0]);
    if (row < 0) row = ends.length;
    ends[row] = s.frames[1];
    return row;
  });
}

/**
 * The feedback a rejection starts from: QC's own, then each swap and issue span in words
 * (each once).
 * @param {{feedback?: string, swaps?: any[], issues?: any[], point_names?: string[]}} review
 */
export function evidenceFeedback(review) {
  const lines = [];
  if (review.feedback && review.feedback.trim()) lines.push(review.feedback.trim());
  const spans = spansOf(review.swaps || [], review.issues || [], review.point_names || []);
  const swaps = spans.filter((s) => s.kind === "swap");
  // An issue inside a swap of its finger is that swap, told once.
  // QC's own feedback that already names the point tells its issues.
  const qc = (review.feedback || "").toLowerCase();
  const named = (/** @type {Span} */ s) => {
    const name = (review.point_names?.[s.points[0]] || "").replace(/_/g, " ").toLowerCase();
    return Boolean(name) && qc.includes(name);
  };
  const told = (/** @type {Span} */ s) => s.kind === "issue" && (named(s) || swaps.some((w) =>
    w.points.includes(s.points[0]) && s.frames[0] <= w.frames[1] && w.frames[0] <= s.frames[1]));
  for (const span of spans.filter((s) => !told(s))) {
    const sentence = `${span.detail[0].toUpperCase()}${span.detail.slice(1)}.`;
    if (!lines.some((l) => l.includes(span.detail))) lines.push(sentence);
  }
  return lines.join("\n").slice(0, 1024);
}

/**
 * The viewport: image px to canvas px and back. ``zoom`` 1 fits the image in the canvas;
 * (cx, cy) is the image point at the canvas' centre.
 * @param {{width: number, height: number}} image
 * @param {{width: number, height: number}} canvas
 * @param {{zoom: number, cx: number, cy: number}} view
 */
export function viewport(image, canvas, view) {
  const fit = Math.min(canvas.width / image.width, canvas.height / image.height);
  const scale = fit * view.zoom;
  const ox = canvas.width / 2 - view.cx * scale, oy = canvas.height / 2 - view.cy * scale;
  return {
    scale,
    /** @param {number} x @param {number} y */
    toCanvas: (x, y) => [ox + x * scale, oy + y * scale],
    /** @param {number} x @param {number} y */
    toImage: (x, y) => [(x - ox) / scale, (y - oy) / scale],
  };
}

/**
 * The view after zooming by ``factor`` about a canvas point (which stays over the same image
 * point); zoom kept within [1, 16].
 * @param {{width: number, height: number}} image
 * @param {{width: number, height: number}} canvas
 * @param {{zoom: number, cx: number, cy: number}} view
 * @param {number} factor  @param {number} x  @param {number} y  canvas px
 */
export function zoomAt(image, canvas, view, factor, x, y) {
  const zoom = Math.min(Math.max(view.zoom * factor, 1), 16);
  if (zoom === 1) return { zoom, cx: image.width / 2, cy: image.height / 2 };
  const [ix, iy] = viewport(image, canvas, view).toImage(x, y);
  const scale = viewport(image, canvas, { ...view, zoom }).scale;
  return { zoom, cx: ix - (x - canvas.width / 2) / scale, cy: iy - (y - canvas.height / 2) / scale };
}

/**
 * The next frame when stepping or playing: within [0, frames - 1]; playing wraps around.
 * @param {number} frame  @param {number} step  @param {number} frames  @param {boolean} [wrap]
 */
export function stepFrame(frame, step, frames, wrap = false) {
  const next = frame + step;
  if (wrap) return ((next % frames) + frames) % frames;
  return Math.min(Math.max(next, 0), frames - 1);
}

/**
 * What one point of one frame shows: the worker's position and own visibility flag, the
 * reference and the error between them (null where absent).
 * @param {any} review  @param {number} frame  @param {number} point
 */
export function pointAt(review, frame, point) {
  const xy = review.track.xy[frame]?.[point];
  const ref = review.reference?.[frame]?.[point];
  const has = (/** @type {any} */ p) => Array.isArray(p) && p[0] !== null && p[1] !== null;
  return {
    xy: has(xy) ? /** @type {[number, number]} */ (xy) : null,
    visible: Boolean(review.track.visible[frame]?.[point]),
    reference: has(ref) ? /** @type {[number, number]} */ (ref) : null,
    referenceShown: review.reference_shown ? Boolean(review.reference_shown[frame]?.[point]) : true,
    error: review.errors?.[frame]?.[point] ?? null,
  };
}

/**
 * The box around one frame's points of the given tracks, or null where there are none.
 * @param {any[]} tracks  arrays of (F, P, 2) px, null where absent
 * @param {number} frame
 */
function frameBox(tracks, frame) {
  let x0 = Infinity, y0 = Infinity, x1 = -Infinity, y1 = -Infinity;
  for (const track of tracks) {
    for (const p of track?.[frame] || []) {
      if (!Array.isArray(p) || p[0] === null || p[1] === null) continue;
      x0 = Math.min(x0, p[0]); y0 = Math.min(y0, p[1]);
      x1 = Math.max(x1, p[0]); y1 = Math.max(y1, p[1]);
    }
  }
  return Number.isFinite(x0) ? { x0, y0, x1, y1 } : null;
}

/**
 * The view that follows the points: zoomed so that the largest box one frame's points make
 * (with a margin) fits, at most 6x and never less than the whole frame, and centred on this
 * frame's points (on the nearest frame that has some, else the image).
 * @param {{width: number, height: number}} image
 * @param {any[]} tracks  arrays of (F, P, 2) px, null where absent
 * @param {number} frame
 * @param {number} frames  F
 * @param {number} [margin]  of the box's size on each side
 */
export function followView(image, tracks, frame, frames, margin = 0.35) {
  let w = 0, h = 0;
  /** @type {ReturnType<typeof frameBox>[]} */
  const boxes = Array.from({ length: frames }, (_, f) => frameBox(tracks, f));
  for (const box of boxes) {
    if (box) { w = Math.max(w, box.x1 - box.x0); h = Math.max(h, box.y1 - box.y0); }
  }
  const near = [...boxes.keys()].filter((f) => boxes[f])
    .sort((a, b) => Math.abs(a - frame) - Math.abs(b - frame))[0];
  if (near === undefined) return { zoom: 1, cx: image.width / 2, cy: image.height / 2 };
  const box = /** @type {NonNullable<ReturnType<typeof frameBox>>} */ (boxes[near]);
  const zoom = Math.min(Math.max(Math.min(image.width / (Math.max(w, 16) * (1 + 2 * margin)),
    image.height / (Math.max(h, 16) * (1 + 2 * margin))), 1), 6);
  return { zoom, cx: (box.x0 + box.x1) / 2, cy: (box.y0 + box.y1) / 2 };
}
