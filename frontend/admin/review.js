/**
 * The assignment review panel: the worker's points replayed over the view's frames beside the
 * reference they are judged against (a line between each pair, coloured by the error), a
 * joint x frame heat map of the errors, a timeline of swap and issue spans, the reasons and
 * the metrics. Drawing only: what to draw comes from replay.js and the review endpoint.
 */

import { el, renderFacts, svg } from "./views.js";
import {
  NO_ERROR, cellAt, errorColour, followView, heatLayout, legendStops, pointAt, spanRows, spansOf,
  stepFrame, viewport, zoomAt,
} from "./replay.js";

/** A heat map cell without an error where the worker marked the point occluded. */
const MARKED_OCCLUDED = "#7d8793";
/** Replay speed, frames per second. */
const PLAY_FPS = 8;
/** Radius of a drawn point, canvas px. */
const DOT = 4;
/** Height of one timeline row, px. */
const SPAN_ROW = 18;

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
    const button = (/** @type {string} */ act, /** @type {string} */ text,
      /** @type {string} */ tip) => el("button", { type: "button", "data-act": act, title: tip },
      [text]);
    const controls = el("div", { class: "replay-controls" }, [
      button("back", "◀", "Previous frame (←)"), this.playButton,
      button("forward", "▶", "Next frame (→)"), this.slider, this.frameLabel,
      button("zoom-out", "−", "Zoom out"), button("zoom-in", "+", "Zoom in (or the wheel)"),
      button("fit", "Frame", "The whole frame"),
      button("points", "Follow", "Zoom to the points and follow them"), this.readonly,
    ]);
    const legend = el("div", { class: "replay-legend" }, [
      el("span", { class: "ramp" }, legendStops().map(([px, colour]) =>
        el("span", { style: `background:${colour}` }, [`${px}${px === 20 ? "+" : ""}`]))),
      el("span", {}, ["px from the reference"]),
      el("span", { class: "key worker" }, ["● worker"]),
      el("span", { class: "key hidden" }, ["○ marked occluded"]),
      el("span", { class: "key ref" }, ["◇ reference"]),
      el("span", { class: "key refhidden" }, ["◇ reference, hidden"]),
    ]);
    this.root.append(this.title, this.note, el("div", { class: "replay-stage" }, [this.canvas]),
      controls, legend, el("h3", {}, ["Error per point and frame"]), this.heatNote,
      el("p", { class: "heat-key muted" }, [
        el("span", { class: "swatch", style: `background:${NO_ERROR}` }), " no error measured ",
        el("span", { class: "swatch", style: `background:${MARKED_OCCLUDED}` }),
        " marked occluded by the worker; click a cell for its frame"]), this.heat,
      el("h3", {}, ["Swaps and issues"]), this.timeline, el("h3", {}, ["Reasons"]),
      this.reasons, el("h3", {}, ["Metrics"]), this.facts);
    host.replaceChildren(this.root);
    this.bind(controls);
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
    this.heat.addEventListener("click", (e) => {
      if (!this.review) return;
      const box = this.heat.getBoundingClientRect();
      const layout = this.heatLayout();
      const cell = cellAt(layout, e.clientX - box.left, e.clientY - box.top,
        this.review.num_frames, this.review.point_names.length);
      if (cell) this.show(cell.frame);
    });
    this.timeline.addEventListener("click", (e) => {
      const frame = /** @type {Element} */ (e.target).closest("[data-first]")
        ?.getAttribute("data-first");
      if (frame !== null && frame !== undefined) this.show(Number(frame));
    });
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
    this.drawHeat();
    this.drawTimeline(width);
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
    this.drawCursor();
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

  /** The frame, the worker's points, the references and the lines between them. */
  draw() {
    const review = this.review;
    if (!review) return;
    const ctx = /** @type {CanvasRenderingContext2D} */ (this.canvas.getContext("2d"));
    const size = this.cssSize(this.canvas);
    const ratio = this.canvas.width / size.width;
    ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
    ctx.fillStyle = "#1d232b";
    ctx.fillRect(0, 0, size.width, size.height);
    const vp = viewport({ width: review.width, height: review.height }, size, this.view);
    const img = this.images[this.frame];
    if (img && img.complete && img.naturalWidth) {
      const [x0, y0] = vp.toCanvas(0, 0);
      ctx.drawImage(img, x0, y0, review.width * vp.scale, review.height * vp.scale);
      this.root.dataset.imageFrame = String(this.frame);
    } else {
      delete this.root.dataset.imageFrame;
    }
    if (review.highlight?.polygon?.length) this.drawOutline(ctx, vp, review.highlight.polygon);
    const points = review.point_names.length;
    const at = Array.from({ length: points }, (_, p) => pointAt(review, this.frame, p));
    this.drawSkeleton(ctx, vp, at);
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
      if (ref) this.drawReference(ctx, ref, q.referenceShown);
    }
    // The worker's points over every line, in point order.
    for (const [p, q] of at.entries()) {
      if (q.xy) this.drawWorker(ctx, vp.toCanvas(...q.xy), q.visible, review.point_colours[p] || "#fff");
    }
  }

  /**
   * @param {CanvasRenderingContext2D} ctx @param {ReturnType<typeof viewport>} vp
   * @param {number[][]} polygon  image px
   */
  drawOutline(ctx, vp, polygon) {
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
   * @param {CanvasRenderingContext2D} ctx @param {ReturnType<typeof viewport>} vp
   * @param {ReturnType<typeof pointAt>[]} at
   */
  drawSkeleton(ctx, vp, at) {
    ctx.strokeStyle = "rgba(255, 255, 255, 0.35)";
    ctx.lineWidth = 1;
    for (const [a, b] of this.review.skeleton || []) {
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
  drawWorker(ctx, at, visible, colour) {
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
   * A white diamond at the reference; hollow where the solve calls an anchored landmark
   * hidden.
   * @param {CanvasRenderingContext2D} ctx @param {number[]} at @param {boolean} shown
   */
  drawReference(ctx, at, shown) {
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

  /** The heat map: one cell per point and frame, coloured by the error; names at the left. */
  drawHeat() {
    const review = this.review;
    const ctx = /** @type {CanvasRenderingContext2D} */ (this.heat.getContext("2d"));
    const size = this.cssSize(this.heat);
    const ratio = this.heat.width / size.width;
    const layout = this.heatLayout();
    ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
    ctx.clearRect(0, 0, size.width, size.height);
    ctx.font = `${Math.min(layout.row, 11)}px system-ui, sans-serif`;
    ctx.textBaseline = "middle";
    const frames = review.num_frames, points = review.point_names.length;
    for (let p = 0; p < points; p += 1) {
      ctx.fillStyle = "#4a5561";
      ctx.fillText(review.point_names[p], 0, layout.top + (p + 0.5) * layout.row,
        layout.left - 4);
      for (let f = 0; f < frames; f += 1) {
        const error = review.errors?.[f]?.[p];
        const hidden = !review.track.visible[f]?.[p];
        ctx.fillStyle = error !== null && error !== undefined ? errorColour(error)
          : hidden ? MARKED_OCCLUDED : NO_ERROR;
        ctx.fillRect(layout.left + f * layout.cell, layout.top + p * layout.row,
          Math.max(layout.cell - 0.5, 0.5), layout.row - 0.5);
      }
    }
    Object.assign(this.heat.dataset, { left: layout.left, top: layout.top,
      cell: layout.cell.toFixed(3), row: layout.row });
  }

  /** The current frame marked on the heat map's and the timeline's cursor. */
  drawCursor() {
    const cursor = this.timeline.querySelector(".cursor");
    if (!cursor || !this.review) return;
    const layout = this.heatLayout();
    cursor.setAttribute("x", String(layout.left + this.frame * layout.cell));
    cursor.setAttribute("width", String(Math.max(layout.cell, 2)));
  }

  /**
   * The timeline: a ruler of frames and a bar per swap or issue span, under the heat map's
   * columns; clicking a span shows its first frame.
   * @param {number} width
   */
  drawTimeline(width) {
    const review = this.review;
    const layout = this.heatLayout(width);
    const spans = spansOf(review.swaps, review.issues, review.point_names);
    const rows = spanRows(spans);
    const height = 16 + SPAN_ROW * Math.max(Math.max(-1, ...rows) + 1, 1);
    this.timeline.setAttribute("viewBox", `0 0 ${width} ${height}`);
    this.timeline.setAttribute("width", String(width));
    this.timeline.setAttribute("height", String(height));
    const x = (/** @type {number} */ f) => layout.left + f * layout.cell;
    const nodes = [svg("rect", { class: "cursor", x: x(0), y: 0, width: layout.cell,
      height })];
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
        svg("rect", { x: x(s.frames[0]), y, width: Math.max(w, 2), height: SPAN_ROW - 3,
          rx: 3 }),
        svg("text", { x: x(s.frames[0]) + 3, y: y + SPAN_ROW / 2 + 2 }, [s.label]),
      ]));
    });
    if (!spans.length) {
      nodes.push(svg("text", { x: layout.left, y: 28, class: "none" },
        ["no swaps or issue spans found"]));
    }
    this.timeline.replaceChildren(...nodes);
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
        : `No read-only link: ${err instanceof Error ? err.message : String(err)}`;
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
