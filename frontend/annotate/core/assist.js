/**
 * Assisted annotation: tracking proposals between a worker's keyframes, positions pre-filled
 * from the other views, and epipolar lines from the views already labelled.
 *
 * Positions are image pixels of this view, frames are clip frame indices. Nothing here writes
 * on its own except a re-track after a correction; every write, of one point or of every point,
 * is one store batch (setTracks), so one undo step:
 *
 *   Track   asks POST /api/annotate/proposals for the span between the keyframes the worker set
 *           around the current frame (or every point over the clip) and holds the answer as
 *           ghosts. Past the last keyframe (or before the first) it follows the point from
 *           that one keyframe until the tracker's checks stop it, and says where and why.
 *           Accept writes each proposal that holds on a frame the worker has viewed since
 *           (stepped to or played through) as a "tracked" keyframe; the frames not viewed
 *           stay proposals. Discard drops them. Frames where the tracker lost the point stay
 *           interpolated.
 *   Re-track  a point placed or dragged inside a run of tracked keyframes splits it: the
 *           tracked keyframes between the nearest keyframes the worker set on each side are
 *           proposed again from the new keyframe and replaced (or removed where none holds).
 *           Points corrected together (a skeleton or finger drag) are re-tracked together.
 *           Toggling occlusion moves nothing, so it re-tracks nothing: what was tracked on
 *           either side of the toggled frame stays.
 *   Follow hand  (hand tasks) asks POST /api/annotate/model-follow for the hand model carried
 *           through the view's depth from the worker's keyframes (a job on the server's queue:
 *           asked again every few seconds while it says it is preparing) and holds the answer
 *           as ghosts, accepted or discarded as Track's.
 *   Use suggestions  writes GET /api/annotate/suggestions' positions as "prefilled"
 *           keyframes, never over a keyframe the worker set by hand.
 *
 * The keyframe arithmetic is in proposals.js, the epipolar geometry in epipolar.js. DOM-free:
 * the page passes the store, the API client and callbacks in (assist-draw.js draws it).
 */

import { epipolarLines } from "./epipolar.js";
import {
  HAND_SOURCES, acceptViewed, allSpans, countTracked, handKeyedBefore, heldFrames, heldRuns,
  keyframeRows, modelProposals, modelText, openSpanAround, openSpans, prefillEntries,
  proposalEntries, proposalRequest, proposalsFrom, retrackSpans, sourceOf, spanAround, stopText,
  trackedText,
} from "./proposals.js";
import { ViewedFrames } from "./viewed.js";

/** The store label of an occlusion toggle (AnnotationStore.toggleVisibility). */
const TOGGLE_LABEL = "toggle occluded";

/** Quiet time (ms) after the last edit of a drag before a re-track is asked for. */
const RETRACK_DELAY_MS = 300;
/** While the server prepares fitted suggestions (a job on its worker queue), the page asks
 * again this often (ms), for at most SUGGEST_POLL_LIMIT_MS. */
const SUGGEST_POLL_MS = 4000;
const SUGGEST_POLL_LIMIT_MS = 180000;

/**
 * @typedef {import("./proposals.js").PointProposal} PointProposal
 * @typedef {import("./proposals.js").SourcedKeyframe} SourcedKeyframe
 * @typedef {import("./proposals.js").Entry} Entry
 */

/** Why a request failed, for the status line. @param {any} err */
function reason(err) {
  return err && err.message ? err.message : err;
}

/** A server's reason as a sentence: "The hand model is ….". @param {string} text */
function sentence(text) {
  const t = String(text || "").trim();
  return t ? `${t[0].toUpperCase()}${t.slice(1)}${/[.!?]$/.test(t) ? "" : "."}` : "";
}

/** @param {number} ms */
const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));

/**
 * The assistance of one page: proposals shown as ghosts, the task's suggestions, the epipolar
 * lines' toggle, re-tracks after corrections, and a status line for the worker.
 */
export class Assist {
  /**
   * @param {Object} o
   * @param {import("./store.js").AnnotationStore} o.store
   * @param {{proposals: (body: object) => Promise<any>, suggestions: () => Promise<any>,
   *          modelFollow?: (body: object) => Promise<any>}} o.api
   * @param {boolean} [o.handModel]  whether the hand model's follow is offered (hand tasks)
   * @param {() => boolean} o.editable  whether the page may write now (edit mode, not locked)
   * @param {() => {frame: number, active: number}} o.where  the editor's frame and point
   * @param {() => void} o.onChange  ghosts, lines or status changed: redraw
   * @param {number} [o.retrackDelayMs]
   * @param {number} [o.suggestPollMs]  @param {number} [o.suggestPollLimitMs]
   */
  constructor({ store, api, editable, where, onChange, handModel = false,
    retrackDelayMs = RETRACK_DELAY_MS, suggestPollMs = SUGGEST_POLL_MS,
    suggestPollLimitMs = SUGGEST_POLL_LIMIT_MS }) {
    this.store = store;
    this.handModel = handModel && typeof api.modelFollow === "function";
    this.api = api;
    this.editable = editable;
    this.where = where;
    this.onChange = onChange;
    this.retrackDelayMs = retrackDelayMs;
    this.suggestPollMs = suggestPollMs;
    this.suggestPollLimitMs = suggestPollLimitMs;
    /** @type {null|{points: PointProposal[], counts: {tracked: number, total: number}}} */
    this.proposals = null;
    /** The cells viewed since the proposals were shown (Enter accepts only those). */
    this.viewed = new ViewedFrames();
    /** @type {import("./proposals.js").FollowStop[]} where followed points stopped */
    this.stops = [];
    /** @type {Map<number, {xy: Array<number[]|null>, visible: Array<boolean|null>}>} */
    this.suggestions = new Map();
    /** Labelled views' fundamental matrices and points (GET /api/annotate/suggestions). */
    this.epipolar = [];
    /** The suggestions' quiet line: where they come from, or why there are none. */
    this.suggestNote = "";
    this.showLines = true;
    /** @type {{kind: "none"|"busy"|"info"|"ok"|"warn"|"error", text: string}} */
    this.status = { kind: "none", text: "" };
    this._tracking = false;
    this._writing = false;
    this._inFlight = 0;
    /** @type {Map<number, number>} re-tracks waiting: point -> frame of its correction */
    this._retracks = new Map();
    /** The timer that starts the waiting re-tracks once the edits settle. */
    this._retrackTimer = null;
    store.subscribe((change) => this._onStoreChange(change));
  }

  /** True while a request or a re-track is under way (tests wait for it). */
  get pending() {
    return this._tracking || this._inFlight > 0 || this._retracks.size > 0;
  }

  // ---- tracking ---------------------------------------------------------------------------

  /**
   * Asks for proposals: the active point between its anchors around the current frame, or
   * every point over the whole clip. Resolves to whether proposals are shown.
   * @param {boolean} allPoints
   */
  async track(allPoints) {
    if (!this.editable() || this._tracking) return false;
    const { frame, active } = this.where();
    const points = allPoints ? [...Array(this.store.numPoints).keys()] : [active];
    const spans = new Map();
    const numFrames = this.store.numFrames;
    for (const p of points) {
      const keyframes = this.store.keyframes(p);
      const found = allPoints
        ? [...allSpans(keyframes), ...openSpans(keyframes, numFrames)]
        : spanAround(keyframes, frame);
      if (!found.length && !allPoints) found.push(...openSpanAround(keyframes, frame, numFrames));
      if (found.length) spans.set(p, found.sort((a, b) => a[0] - b[0]));
    }
    if (!spans.size) {
      this._say("warn", allPoints
        ? "Nothing to track: place a point visible on a frame first."
        : "Tracking starts from a visible keyframe you set: place this point on a frame " +
          "(it is followed from there), or on both sides of this frame.");
      return false;
    }
    this._tracking = true;
    this._say("busy", "Tracking…");
    try {
      const answer = await this.api.proposals(
        proposalRequest(spans, (p) => this.store.keyframes(p), numFrames));
      const shown = proposalsFrom(answer, spans);
      const counts = countTracked(shown);
      this.proposals = { points: shown, counts };
      this.stops = (answer.stops || []).filter((s) => spans.has(s.point));
      this.viewed.clear();
      this.noteViewed(this.where().frame, points);
      this._say("info", `${this._stopsText()}${trackedText(counts)} (cyan rings). Step ` +
        "through them: Enter accepts the frames you have viewed, Esc discards.");
      return true;
    } catch (err) {
      this._say("error", `Tracking failed: ${reason(err)}`);
      return false;
    } finally {
      this._tracking = false;
    }
  }

  /**
   * Asks for the hand model's follow from every point's keyframes (hand tasks), waiting while
   * the server prepares it, and shows it as ghosts. Resolves to whether proposals are shown.
   */
  async followModel() {
    if (!this.handModel || !this.editable() || this._tracking) return false;
    const tracks = [];
    for (let p = 0; p < this.store.numPoints; p++) {
      const keyframes = keyframeRows(this.store.keyframes(p));
      if (keyframes.length) tracks.push({ point: p, keyframes });
    }
    const body = { tracks };
    const here = this.where().frame;
    if (handKeyedBefore(tracks, here)) body.begin = here;
    this._tracking = true;
    this._say("busy", "Asking the hand model…");
    try {
      const started = Date.now();
      let answer = await this.api.modelFollow(body);
      while (answer.preparing) {
        if (Date.now() - started >= this.suggestPollLimitMs) {
          this._say("warn", "The hand model is taking longer than expected: press M again " +
            "in a minute.");
          return false;
        }
        this._say("busy", `${sentence(answer.reason)} This takes about a second a frame.`);
        await sleep(this.suggestPollMs);
        answer = await this.api.modelFollow(body);
      }
      const shown = answer.available ? modelProposals(answer, this.store.numFrames) : [];
      if (!shown.length) {
        this._say("warn", answer.available
          ? "The hand model proposes nothing beyond your keyframes here."
          : sentence(answer.reason));
        return false;
      }
      this.proposals = { points: shown, counts: countTracked(shown) };
      this.stops = [];
      this.viewed.clear();
      this.noteViewed(this.where().frame, shown.map((p) => p.point));
      this._say("info", modelText(answer, this.store.numFrames));
      return true;
    } catch (err) {
      this._say("error", `The hand model failed: ${reason(err)}`);
      return false;
    } finally {
      this._tracking = false;
    }
  }

  /**
   * Records that `frame` is shown with these points drawn (the page calls it on every frame
   * it shows while proposals are up, playback included).
   * @param {number} frame @param {Iterable<number>} points
   */
  noteViewed(frame, points) {
    if (this.proposals) this.viewed.mark(frame, points);
  }

  /**
   * Writes the shown proposals as "tracked" keyframes on the frames the worker has viewed;
   * the others stay shown. @returns {boolean}
   */
  accept() {
    if (!this.proposals || !this.editable()) return false;
    const { points, counts } = this.proposals;
    const writes = [];
    const rest = [];
    let taken = 0;
    let skipped = 0;
    for (const p of points) {
      const part = acceptViewed(this.store.keyframes(p.point), p,
        (f) => this.viewed.has(p.point, f));
      writes.push([p.point, part.entries]);
      taken += part.taken;
      skipped += part.skipped;
      if (part.rest) rest.push(part.rest);
    }
    this.proposals = rest.length ? { points: rest, counts } : null;
    this._write(writes, "accept tracking");
    const frames = taken === 1 ? "frame" : "frames";
    this._say(skipped ? "warn" : "ok", skipped
      ? `Accepted ${taken} tracked ${frames} you have viewed; ${skipped} not yet viewed ` +
        "stay suggestions (cyan): step through them, then press Enter again."
      : `Accepted: ${taken} tracked ${frames} (${trackedText(counts)}).`);
    return true;
  }

  /** Drops the shown proposals. @returns {boolean} whether there were any */
  discard() {
    if (!this.proposals) return false;
    this.proposals = null;
    this.stops = [];
    this._say("none", "");
    return true;
  }

  /** "Point 3 tracked to frame 31; stopped: lost the point. " (or the earliest of several). */
  _stopsText() {
    if (!this.stops.length) return "";
    const n = this.store.numFrames;
    const first = this.stops.reduce((a, b) =>
      (Math.abs(b.reached - b.from_frame) < Math.abs(a.reached - a.from_frame) ? b : a));
    const text = stopText(first, n);
    if (this.stops.length === 1) return `${text[0].toUpperCase()}${text.slice(1)}. `;
    return `${this.stops.length} points followed from one keyframe; the shortest ${text}. `;
  }

  // ---- corrections ------------------------------------------------------------------------

  /** A keyframe set by hand inside a run of tracked keyframes re-tracks around it. */
  _onStoreChange(change) {
    if (this._writing || change.cause === "saved") return;
    const points = change.points || (change.point === null ? [] : [change.point]);
    this._dropStaleProposals(points);
    if (change.cause !== "edit" || change.label === TOGGLE_LABEL) return;
    const corrected = new Map();
    for (const point of points) {
      for (const frame of [...change.created, ...change.updated]) {
        const k = this.store.keyframeAt(point, frame);
        if (!k || !HAND_SOURCES.includes(sourceOf(k))) continue;
        if (retrackSpans(this.store.keyframes(point), frame, this.store.numFrames).length) {
          corrected.set(point, frame);
        }
      }
    }
    if (corrected.size) this._scheduleRetrack(corrected);
  }

  /** Shown proposals of points whose keyframes changed were tracked from other anchors. */
  _dropStaleProposals(points) {
    if (!this.proposals) return;
    const kept = this.proposals.points.filter((p) => !points.includes(p.point));
    if (kept.length === this.proposals.points.length) return;
    this.proposals = kept.length ? { points: kept, counts: countTracked(kept) } : null;
    this._say("warn", "Proposals dropped for a point whose keyframes changed; press T to " +
      "track it again.");
  }

  /**
   * Waits for the edits to settle (every step of a drag is an edit), then re-tracks every
   * point corrected meanwhile in one request and one write.
   * @param {Map<number, number>} corrected  point -> frame of its correction
   */
  _scheduleRetrack(corrected) {
    for (const [point, frame] of corrected) this._retracks.set(point, frame);
    clearTimeout(this._retrackTimer);
    this._retrackTimer = setTimeout(() => {
      this._retrackTimer = null;
      const waiting = new Map(this._retracks);
      this._retracks.clear();
      this._retrack(waiting);
    }, this.retrackDelayMs);
  }

  /**
   * Proposes again, for each corrected point, on the sides of its correction that hold tracked
   * keyframes, and replaces them: one request, one undo step.
   * @param {Map<number, number>} corrected  point -> frame of its correction
   */
  async _retrack(corrected) {
    if (!this.editable()) return;
    /** @type {Map<number, {keyframes: SourcedKeyframe[], spans: number[][]}>} */
    const asked = new Map();
    for (const [point, frame] of corrected) {
      const keyframes = this.store.keyframes(point);
      const spans = retrackSpans(keyframes, frame, this.store.numFrames);
      if (spans.length) asked.set(point, { keyframes, spans });
    }
    if (!asked.size) return;
    const spans = new Map([...asked].map(([point, a]) => [point, a.spans]));
    const body = proposalRequest(spans, (point) => asked.get(point).keyframes,
      this.store.numFrames);
    const editCount = this.store.editCount;
    this._inFlight += 1;
    let answer;
    try {
      answer = await this.api.proposals(body);
    } catch (err) {
      this._say("error", `Re-tracking failed: ${reason(err)}`);
      return;
    } finally {
      this._inFlight -= 1;
    }
    if (!this.editable()) return;
    // Edited meanwhile: ask again from what is there now, never write over newer work.
    if (this.store.editCount !== editCount) {
      const again = new Map([...corrected].filter(([p]) => !this._retracks.has(p)));
      if (again.size) this._scheduleRetrack(again);
      return;
    }
    const proposals = proposalsFrom(answer, spans);
    // Written by the page itself after the worker's correction: not an action of theirs.
    this._write(proposals.map((p) => [p.point, proposalEntries(asked.get(p.point).keyframes, p)]),
      "re-track", true);
    const around = asked.size === 1
      ? "your correction" : `your corrections of ${asked.size} points`;
    this._say("ok", `Re-tracked frames ${body.first_frame}-${body.last_frame} around ${around}: ` +
      `${trackedText(countTracked(proposals))}.`);
  }

  // ---- suggestions ------------------------------------------------------------------------

  /**
   * Reads the task's suggestions (edit mode). While the server says they are being prepared
   * (fitted on its worker queue), shows its reason and asks again every few seconds, for a
   * few minutes at most.
   */
  async loadSuggestions() {
    let answer;
    const started = Date.now();
    for (;;) {
      try {
        answer = await this.api.suggestions();
      } catch (err) {
        this.suggestNote = `No suggestions: ${reason(err)}`;
        this.onChange();
        return;
      }
      if (!answer.preparing) break;
      if (Date.now() - started >= this.suggestPollLimitMs) {
        this.suggestNote = "No suggestions: they are taking longer than expected to prepare; " +
          "reload the page later to see them.";
        this.onChange();
        return;
      }
      this.suggestNote = answer.reason || "Suggestions are being prepared.";
      this.onChange();
      await new Promise((resolve) => setTimeout(resolve, this.suggestPollMs));
    }
    this.epipolar = Array.isArray(answer.epipolar) ? answer.epipolar : [];
    if (answer.available) {
      for (const s of answer.points || []) this.suggestions.set(s.point, s);
      const n = Array.isArray(answer.views) ? answer.views.length : Number(answer.views) || 0;
      // Fitted from one or two views (the hand model, or the object's mesh, on their labels
      // and depth): rougher than triangulated.
      const how = answer.method === "fitted" ? ", fitted: check each" : "";
      this.suggestNote = `Suggestions from ${n} other ${n === 1 ? "view" : "views"}${how} ` +
        "(magenta rings). U: this point; Shift+U: every point.";
    } else {
      this.suggestNote = answer.reason || "No suggestions for this task yet.";
    }
    this.onChange();
  }

  /**
   * Writes the suggestions of the active point (or every point) as "prefilled" keyframes.
   * @param {boolean} allPoints @returns {boolean}
   */
  useSuggestions(allPoints) {
    if (!this.editable() || !this.suggestions.size) return false;
    const { active } = this.where();
    const points = allPoints ? [...this.suggestions.keys()] : [active];
    const writes = points.filter((p) => this.suggestions.has(p)).map((p) =>
      [p, prefillEntries(this.store.keyframes(p), this.suggestions.get(p))]);
    const count = writes.reduce((n, [, entries]) => n + entries.length, 0);
    if (!count) {
      this._say("warn", "No suggestions left to use here: every suggested frame is keyed by you.");
      return false;
    }
    this._write(writes, "use suggestions");
    const who = allPoints ? `${writes.length} points` : "this point";
    this._say("ok", `Used ${count} suggested keyframes for ${who}: step through the frames ` +
      "and drag any that are off.");
    return true;
  }

  /** @returns {boolean} whether epipolar lines are shown now */
  toggleLines() {
    this.showLines = !this.showLines;
    this.onChange();
    return this.showLines;
  }

  // ---- what to draw -----------------------------------------------------------------------

  /**
   * The assistance at one frame: tracking ghosts, the path of the active point's proposals
   * (of every proposed point's when only one is proposed) in runs of consecutive held frames,
   * the active point's suggestion while it is not used, and its epipolar lines.
   * @param {number} frame @param {number} active
   */
  layer(frame, active) {
    const ghosts = [];
    const proposed = this.proposals ? this.proposals.points : [];
    for (const p of proposed) {
      const path = p.point === active || proposed.length === 1 ? heldRuns(p) : [];
      const i = frame - p.first;
      const here = p.ok[i] && p.spans.some(([a, b]) => frame > a && frame < b) ? p.xy[i] : null;
      ghosts.push({ point: p.point, xy: here, path });
    }
    const s = this.suggestions.get(active);
    const k = this.store.keyframeAt(active, frame);
    const used = k && ["prefilled", "edited"].includes(sourceOf(k));
    const suggestion = s && s.xy[frame] && !used
      ? { point: active, xy: s.xy[frame], visible: s.visible[frame] !== false } : null;
    const lines = this.showLines ? epipolarLines(this.epipolar, active, frame) : [];
    return { ghosts, suggestion, lines };
  }

  /** Per point with proposals shown, the frames they hold at (for the timeline). */
  timelineMarks() {
    return (this.proposals ? this.proposals.points : [])
      .map((p) => ({ point: p.point, frames: heldFrames(p) }));
  }

  /** Where each followed point stopped (for the timeline), until the next track or discard. */
  stopMarks() {
    return this.stops.map((s) => ({ point: s.point, frame: s.reached, direction: s.direction,
      stopped: s.stopped }));
  }

  // ---- internals --------------------------------------------------------------------------

  /**
   * One store batch over every point written (one undo step); the store changes it causes are
   * not corrections.
   * @param {Array<[number, Entry[]]>} writes  [point, entries] @param {string} label
   */
  _write(writes, label, automatic = false) {
    this._writing = true;
    try {
      const groups = writes.filter(([, entries]) => entries.length)
        .map(([point, entries]) => ({ point, entries }));
      this.store.setTracks(groups, { label, automatic });
    } finally {
      this._writing = false;
    }
    this.onChange();
  }

  _say(kind, text) {
    this.status = { kind, text };
    this.onChange();
  }
}
