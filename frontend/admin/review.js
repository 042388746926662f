/**
 * The assignment review panel: the worker's points replayed over the view's frames beside the
 * reference they are judged against (a line between each pair, coloured by the error), a
 * joint x frame heat map of the errors, a timeline of swap and issue spans, the reasons and
 * the metrics. Drawing only: what to draw comes from core/replay.js and the review endpoint.
 */

import { el, svg } from "../common/dom.js";
import { errorText } from "../common/notice.js";
import { renderFacts } from "./views.js";
import {
  NO_ERROR, cellAt, followView, heatLayout, legendStops, stepFrame, zoomAt,
} from "./core/replay.js";
import { MARKED_OCCLUDED, drawFrame, drawHeat, drawTimeline, moveCursor } from "./review-draw.js";

/** Replay speed, frames per second. */
const PLAY_FPS = 8;

/**
 * The metric rows of the panel: metrics.js's readable rows when the page has them, the plain
 * facts otherwise.
 * @param {HTMLElement} list  a <dl>
 * @param {any} review
 */
async function renderMetrics(list, review) {
  try {
    const { metricRows } = await import("./metrics.js");
    const rows = /** @type {any[]} */ (metricRows(review));
    list.replaceChildren(...rows.flatMap((r) => [
      el("dt", { title: r.explain || r.name }, [r.label || r.name]),
      el("dd", { "data-review-metric": r.name, title: r.explain || "",
        class: r.over ? "over" : r.value === "–" ? "muted" : "" },
      [String(r.value), r.threshold ? el("span", { class: "muted" }, [` (${r.threshold})`]) : ""]),
    ]));
  } catch {
    renderFacts(list, review);
    // The report's own facts beside this panel keep their data-fact names to themselves.
    for (const dd of list.querySelectorAll("[data-fact]")) {
      dd.setAttribute("data-review-metric", dd.getAttribute("data-fact") || "");
      dd.removeAttribute("data-fact");
    }
  }
}

/** The replay's key: the error colour ramp and the marks of the worker and the reference. */
function replayLegend() {
  return el("div", { class: "replay-legend" }, [
    el("span", { class: "ramp" }, legendStops().map(([px, colour]) =>
      el("span", { style: `background:${colour}` }, [`${px}${px === 20 ? "+" : ""}`]))),
    el("span", {}, ["px from the reference"]),
    el("span", { class: "key worker" }, ["● worker"]),
    el("span", { class: "key hidden" }, ["○ marked occluded"]),
    el("span", { class: "key ref" }, ["◇ reference"]),
    el("span", { class: "key refhidden" }, ["◇ reference, hidden"]),
  ]);
}

/** The heat map's key: the grey of no error and of a point marked occluded. */
function heatKey() {
  return el("p", { class: "heat-key muted" }, [
    el("span", { class: "swatch", style: `background:${NO_ERROR}` }), " no error measured ",
    el("span", { class: "swatch", style: `background:${MARKED_OCCLUDED}` }),
    " marked occluded by the worker; click a cell for its frame"]);
}

export class ReviewPanel {
  /**
   * @param {HTMLElement} host  emptied and filled with the panel
   * @param {{request: (method: string, path: string, body?: any) => Promise<any>}} api
   */
  constructor(host, api) {
    this.api = api;
    /** @type {any} */ this.review = null;
    this.frame = 0;
    /** @type {number|null} */ this.timer = null;
    this.view = { zoom: 1, cx: 0, cy: 0 };
    /** Whether the view follows the points from frame to frame (until zoomed by hand). */
    this.follow = true;
    /** @type {HTMLImageElement[]} */ this.images = [];
    this.root = el("div", { class: "review", "data-review": "" });
    this.title = el("h2", { class: "review-title" });
    this.note = el("p", { class: "review-note", hidden: "" });
    this.canvas = /** @type {HTMLCanvasElement} */ (el("canvas", { class: "replay",
      "aria-label": "the worker's points over the frame" }));
    this.slider = /** @type {HTMLInputElement} */ (el("input", { type: "range", min: 0, value: 0,
      class: "scrubber", "aria-label": "frame" }));
    this.frameLabel = el("span", { class: "frame-label" });
    this.playButton = el("button", { type: "button", "data-act": "play", title: "Play (Space)" },
      ["▶ Play"]);
    this.readonly = /** @type {HTMLButtonElement} */ (el("button", { type: "button",
      "data-act": "readonly" }, ["Open in the annotation page (read-only)"]));
    this.heat = /** @type {HTMLCanvasElement} */ (el("canvas", { class: "heatmap",
      "aria-label": "error per point and frame" }));
    this.heatNote = el("p", { class: "muted heat-note", hidden: "" },
      ["No errors per frame without a reference: the cells stay grey."]);
    this.timeline = svg("svg", { class: "timeline", role: "img",
      "aria-label": "swap and issue spans" });
    this.reasons = el("ul", { class: "reasons" });
    this.facts = el("dl", { class: "facts" });
    const controls = this.replayControls();
    this.root.append(this.title, this.note, el("div", { class: "replay-stage" }, [this.canvas]),
      controls, replayLegend(), el("h3", {}, ["Error per point and frame"]), this.heatNote,
      heatKey(), this.heat, el("h3", {}, ["Swaps and issues"]), this.timeline,
      el("h3", {}, ["Reasons"]), this.reasons, el("h3", {}, ["Metrics"]), this.facts);
    host.replaceChildren(this.root);
    this.bind(controls);
  }

  /** The buttons, slider and frame label under the replay. */
  replayControls() {
    const button = (/** @type {string} */ act, /** @type {string} */ text,
      /** @type {string} */ tip) => el("button", { type: "button", "data-act": act, title: tip },
      [text]);
    return el("div", { class: "replay-controls" }, [
      button("back", "◀", "Previous frame (←)"), this.playButton,
      button("forward", "▶", "Next frame (→)"), this.slider, this.frameLabel,
      button("zoom-out", "−", "Zoom out"), button("zoom-in", "+", "Zoom in (or the wheel)"),
      button("fit", "Frame", "The whole frame"),
      button("points", "Follow", "Zoom to the points and follow them"), this.readonly,
    ]);
  }

  /** @param {HTMLElement} controls */
  bind(controls) {
    controls.addEventListener("click", (e) => {
      const act = /** @type {HTMLElement} */ (e.target).closest("button")?.dataset.act;
      if (act === "back") this.step(-1);
      else if (act === "forward") this.step(1);
      else if (act === "play") this.togglePlay();
      else if (act === "zoom-in") this.zoom(1.5);
      else if (act === "zoom-out") this.zoom(1 / 1.5);
      else if (act === "fit") this.zoom(0);
      else if (act === "points") this.zoom(-1);
      else if (act === "readonly") this.openReadonly();
    });
    this.slider.addEventListener("input", () => this.show(Number(this.slider.value)));
    this.canvas.addEventListener("wheel", (e) => {
      e.preventDefault();
      const box = this.canvas.getBoundingClientRect();
      this.zoom(e.deltaY < 0 ? 1.25 : 0.8, e.clientX - box.left, e.clientY - box.top);
    }, { passive: false });
    this.heat.addEventListener("mousemove", (e) => {
      const cell = this.cellOf(e);
      const error = cell ? this.review.errors?.[cell.frame]?.[cell.point] : null;
      this.heat.title = !cell ? "" : `${this.review.point_names[cell.point]}, frame ${cell.frame}: `
        + (error === null || error === undefined ? "no error measured" : `${error.toFixed(1)} px`)
        + (this.review.track.visible[cell.frame]?.[cell.point] ? "" : ", marked occluded");
    });
    this.heat.addEventListener("click", (e) => {
      const cell = this.cellOf(e);
      if (cell) this.show(cell.frame);
    });
    this.timeline.addEventListener("click", (e) => {
      const frame = /** @type {Element} */ (e.target).closest("[data-first]")
        ?.getAttribute("data-first");
      if (frame !== null && frame !== undefined) this.show(Number(frame));
    });
  }

  /**
   * The heat map cell under the mouse, or null.
   * @param {MouseEvent} e
   */
  cellOf(e) {
    if (!this.review) return null;
    const box = this.heat.getBoundingClientRect();
    return cellAt(this.heatLayout(), e.clientX - box.left, e.clientY - box.top,
      this.review.num_frames, this.review.point_names.length);
  }

  /**
   * Show a review (GET /api/qc/reports/{id}/review) from its first frame.
   * @param {any} review
   */
  load(review) {
    this.stop();
    this.review = review;
    this.frame = 0;
    this.follow = true;
    this.view = this.pointsView();
    this.root.dataset.zoom = this.view.zoom.toFixed(2);
    this.root.dataset.assignment = String(review.assignment_id);
    this.title.textContent = `Assignment ${review.assignment_id} · ${review.worker_id} · `
      + `${review.sequence} view ${review.serial} · ${review.target_key}`;
    this.note.textContent = review.reference_note
      ? `Reference unavailable: ${review.reference_note}.` : "";
    this.note.hidden = !review.reference_note;
    this.slider.max = String(review.num_frames - 1);
    this.readonly.disabled = false;
    this.readonly.title = "A read-only copy of the worker's annotation page, in a new tab";
    this.images = review.frames.urls.map((/** @type {string} */ url, /** @type {number} */ i) => {
      const img = new Image();
      img.onload = () => { if (i === this.frame) this.draw(); };
      img.src = url;
      return img;
    });
    this.reasons.replaceChildren(...(review.reasons.length
      ? review.reasons.map((/** @type {string} */ r) => el("li", {}, [r]))
      : [el("li", { class: "muted" }, ["none: QC found nothing wrong"])]));
    renderMetrics(this.facts, review);
    this.heatNote.hidden = Boolean(review.errors);
    this.layout();
  }

  /** Size the canvases to the panel's width and redraw everything. */
  layout() {
    if (!this.review) return;
    const width = Math.max(this.root.clientWidth, 320);
    const ratio = window.devicePixelRatio || 1;
    const aspect = this.review.height / this.review.width;
    const stage = Math.min(width, Math.round((window.innerHeight * 0.5) / aspect));
    for (const [canvas, w, h] of /** @type {[HTMLCanvasElement, number, number][]} */ ([
      [this.canvas, stage, Math.round(stage * aspect)],
      [this.heat, width, this.heatLayout(width).height]])) {
      canvas.style.width = `${w}px`;
      canvas.style.height = `${h}px`;
      canvas.width = Math.round(w * ratio);
      canvas.height = Math.round(h * ratio);
    }
    drawHeat(this.heat, this.review, this.heatLayout(width));
    drawTimeline(/** @type {SVGSVGElement} */ (this.timeline), this.review,
      this.heatLayout(width), width);
    this.show(this.frame);
  }

  /** @param {number} [width] */
  heatLayout(width) {
    const w = width ?? (parseFloat(this.heat.style.width) || this.root.clientWidth);
    return heatLayout(this.review.num_frames, this.review.point_names.length, w);
  }

  /** @param {number} frame */
  show(frame) {
    if (!this.review) return;
    this.frame = stepFrame(frame, 0, this.review.num_frames);
    this.slider.value = String(this.frame);
    this.frameLabel.textContent = `frame ${this.frame} / ${this.review.num_frames - 1}`;
    this.root.dataset.frame = String(this.frame);
    if (this.follow) this.view = this.pointsView();
    this.draw();
    moveCursor(/** @type {SVGSVGElement} */ (this.timeline), this.heatLayout(), this.frame);
  }

  /** @param {number} by */
  step(by) {
    this.stop();
    this.show(stepFrame(this.frame, by, this.review.num_frames));
  }

  togglePlay() {
    if (this.timer !== null) {
      this.stop();
      return;
    }
    this.timer = window.setInterval(() =>
      this.show(stepFrame(this.frame, 1, this.review.num_frames, true)), 1000 / PLAY_FPS);
    this.playButton.textContent = "❚❚ Pause";
    this.root.dataset.playing = "true";
  }

  stop() {
    if (this.timer !== null) window.clearInterval(this.timer);
    this.timer = null;
    this.playButton.textContent = "▶ Play";
    delete this.root.dataset.playing;
  }

  /**
   * Zoom by ``factor`` about a canvas point (the centre by default); 0 fits the whole frame,
   * -1 the points.
   * @param {number} factor @param {number} [x] @param {number} [y]
   */
  zoom(factor, x, y) {
    if (!this.review) return;
    const image = { width: this.review.width, height: this.review.height };
    const canvas = this.cssSize(this.canvas);
    this.follow = factor < 0;
    this.view = factor === 0 ? { zoom: 1, cx: image.width / 2, cy: image.height / 2 }
      : factor < 0 ? this.pointsView() : zoomAt(image, canvas, this.view, factor, x ?? canvas.width / 2, y ?? canvas.height / 2);
    this.root.dataset.zoom = this.view.zoom.toFixed(2);
    this.draw();
  }

  /** The view that follows the worker's points and the reference at the current frame. */
  pointsView() {
    const review = this.review;
    // An object's outline stays in view beside its landmarks.
    const outline = review.highlight?.polygon?.length
      ? Array(review.num_frames).fill(review.highlight.polygon) : null;
    return followView({ width: review.width, height: review.height },
      [review.track.xy, review.reference, outline], this.frame, review.num_frames);
  }

  /** @param {HTMLCanvasElement} canvas */
  cssSize(canvas) {
    return { width: parseFloat(canvas.style.width) || canvas.width,
      height: parseFloat(canvas.style.height) || canvas.height };
  }

  /** The current frame: picture, points, references and the lines between them. */
  draw() {
    if (!this.review) return;
    const drawn = drawFrame(this.canvas, this.review, this.frame, this.view,
      this.images[this.frame]);
    if (drawn) this.root.dataset.imageFrame = String(this.frame);
    else delete this.root.dataset.imageFrame;
  }

  /** Ask for a read-only link to the worker's annotation page and open it in a new tab. */
  async openReadonly() {
    if (!this.review) return;
    const tab = window.open("", "_blank");
    try {
      const reply = await this.api.request("POST",
        `/assignments/${this.review.assignment_id}/readonly-link`);
      const url = new URL(reply.url, location.href).href;
      if (tab) tab.location.href = url;
      else window.open(url, "_blank");
    } catch (err) {
      tab?.close();
      const status = /** @type {any} */ (err)?.status;
      this.readonly.disabled = true;
      this.readonly.title = status === 404 || status === 405
        ? "The server does not offer read-only annotation links yet"
        : `No read-only link: ${errorText(err)}`;
    }
  }

  /** Leave the panel: stop playing. */
  close() {
    this.stop();
  }
}

/** @type {WeakMap<HTMLElement, ReviewPanel>} */
const panels = new WeakMap();

/**
 * Show an assignment's review in ``host`` (one panel per host, made on first use).
 * @param {HTMLElement} host
 * @param {{request: (method: string, path: string, body?: any) => Promise<any>}} api
 * @param {number} assignmentId
 */
export async function showReviewIn(host, api, assignmentId) {
  let panel = panels.get(host);
  if (!panel) {
    panel = new ReviewPanel(host, api);
    panels.set(host, panel);
  }
  const review = await api.request("GET", `/qc/reports/${assignmentId}/review`);
  host.hidden = false;
  panel.load(review);
  return panel;
}
