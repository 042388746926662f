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
 *           ghosts; Accept writes each proposal that holds as a "tracked" keyframe, Discard
 *           drops them. Frames where the tracker lost the point stay interpolated.
 *   Re-track  a point placed or dragged inside a run of tracked keyframes splits it: the
 *           tracked keyframes between the nearest keyframes the worker set on each side are
 *           proposed again from the new keyframe and replaced (or removed where none holds).
 *           Points corrected together (a skeleton or finger drag) are re-tracked together.
 *   Use suggestions  writes GET /api/annotate/suggestions' positions as "prefilled"
 *           keyframes, never over a keyframe the worker set by hand.
 *
 * Keyframe sources: "placed" (set by hand; a keyframe without source), "edited" (a
 * suggestion the worker changed), "tracked" and "prefilled" (suggestions taken unchanged).
 * Anchors are the keyframes that are not "tracked": tracking runs between them.
 *
 * DOM-free: the page passes the store, the API client and callbacks in.
 */

/** Quiet time (ms) after the last edit of a drag before a re-track is asked for. */
const RETRACK_DELAY_MS = 300;
/** Sources of keyframes the worker set by hand, which suggestions never replace. */
const HAND_SOURCES = ["placed", "edited"];

/**
 * @typedef {{frame: number, x: number|null, y: number|null, visible: boolean,
 *            source?: string}} SourcedKeyframe
 * @typedef {{frame: number, x?: number, y?: number, visible?: boolean, source?: string,
 *            remove?: boolean}} Entry  one write of a store batch
 * @typedef {{point: number, first: number, last: number, spans: number[][],
 *            xy: Array<number[]|null>, ok: boolean[]}} PointProposal
 *   first..last: the frames xy/ok cover (xy[i] is frame first + i); spans: [k0, k1] anchor
 *   pairs whose inner frames the proposal decides
 * @typedef {{serial: string, a: number, b: number, c: number}} EpipolarLine
 *   a x + b y + c = 0 in this view's image px, a^2 + b^2 = 1
 */

/** @param {SourcedKeyframe} k */
export function sourceOf(k) {
  return k.source || "placed";
}

/** @param {SourcedKeyframe} k  a keyframe tracking may start or end at */
function isAnchor(k) {
  return sourceOf(k) !== "tracked";
}

/** @param {SourcedKeyframe} k */
function trackable(k) {
  return k.visible && k.x !== null && k.y !== null;
}

/**
 * The anchor pairs around `frame` (a keyframe, or between two): [[k0, k1]] of the nearest
 * anchors on each side, the span after the frame when it is an anchor itself (the one before
 * at the last anchor). [] when there is no anchor on one side or one of them is occluded.
 * @param {SourcedKeyframe[]} keyframes  sorted by frame @param {number} frame
 * @returns {number[][]}
 */
export function spanAround(keyframes, frame) {
  const anchors = keyframes.filter(isAnchor);
  let i = anchors.findIndex((k) => k.frame > frame);
  if (i < 0) i = anchors.length;
  let before = anchors[i - 1];
  let after = anchors[i];
  if (before && before.frame === frame && !after) {
    after = before;
    before = anchors[i - 2];
  }
  if (!before || !after || !trackable(before) || !trackable(after)) return [];
  return after.frame - before.frame >= 2 ? [[before.frame, after.frame]] : [];
}

/**
 * Every anchor pair of a track worth tracking (both visible, at least 2 frames apart).
 * @param {SourcedKeyframe[]} keyframes @returns {number[][]}
 */
export function allSpans(keyframes) {
  const anchors = keyframes.filter(isAnchor);
  const spans = [];
  for (let i = 1; i < anchors.length; i++) {
    const [a, b] = [anchors[i - 1], anchors[i]];
    if (trackable(a) && trackable(b) && b.frame - a.frame >= 2) spans.push([a.frame, b.frame]);
  }
  return spans;
}

/**
 * The anchors as saved rows [frame, x, y, visible01] (what the proposals route tracks from).
 * @param {SourcedKeyframe[]} keyframes @returns {any[][]}
 */
export function anchorRows(keyframes) {
  return keyframes.filter(isAnchor).map((k) => [k.frame, k.x, k.y, k.visible ? 1 : 0]);
}

/**
 * The store writes that take a proposal: inside each span, a "tracked" keyframe where the
 * proposal holds, and the removal of an older tracked keyframe where it does not. Frames that
 * hold an anchor now (the worker keyed them meanwhile) are left alone.
 * @param {SourcedKeyframe[]} keyframes  the point's keyframes now
 * @param {PointProposal} proposal @returns {Entry[]}
 */
export function proposalEntries(keyframes, proposal) {
  const byFrame = new Map(keyframes.map((k) => [k.frame, k]));
  const entries = [];
  for (const [k0, k1] of proposal.spans) {
    for (let f = k0 + 1; f < k1; f++) {
      const existing = byFrame.get(f);
      if (existing && isAnchor(existing)) continue;
      const i = f - proposal.first;
      const xy = proposal.ok[i] ? proposal.xy[i] : null;
      if (xy) entries.push({ frame: f, x: xy[0], y: xy[1], visible: true, source: "tracked" });
      else if (existing) entries.push({ frame: f, remove: true });
    }
  }
  return entries;
}

/**
 * How many inner span frames a set of proposals holds at.
 * @param {PointProposal[]} proposals @returns {{tracked: number, total: number}}
 */
export function countTracked(proposals) {
  let tracked = 0;
  let total = 0;
  for (const p of proposals) {
    for (const [k0, k1] of p.spans) {
      for (let f = k0 + 1; f < k1; f++) {
        total += 1;
        if (p.ok[f - p.first] && p.xy[f - p.first]) tracked += 1;
      }
    }
  }
  return { tracked, total };
}

/** "12 of 14 frames tracked; 2 left to interpolation". @param {{tracked: number, total: number}} c */
export function trackedText({ tracked, total }) {
  const unit = total === 1 ? "frame" : "frames";
  const left = total - tracked;
  return `${tracked} of ${total} ${unit} tracked; ${left} left to interpolation`;
}

/**
 * The anchor pairs a hand-set keyframe at `frame` re-tracks: each side (the nearest anchor
 * before it to it, it to the nearest anchor after it) that holds tracked keyframes.
 * @param {SourcedKeyframe[]} keyframes @param {number} frame @returns {number[][]}
 */
export function retrackSpans(keyframes, frame) {
  const here = keyframes.find((k) => k.frame === frame);
  if (!here || !isAnchor(here)) return [];
  const anchors = keyframes.filter(isAnchor);
  const i = anchors.indexOf(here);
  const sides = [[anchors[i - 1], here], [here, anchors[i + 1]]];
  return sides
    .filter(([a, b]) => a && b && keyframes.some(
      (k) => !isAnchor(k) && k.frame > a.frame && k.frame < b.frame))
    .map(([a, b]) => [a.frame, b.frame]);
}

/**
 * The store writes that use one point's suggestions: a "prefilled" keyframe at every frame
 * with a suggested position (occluded where the suggestion says so), except at keyframes the
 * worker set by hand.
 * @param {SourcedKeyframe[]} keyframes
 * @param {{xy: Array<number[]|null>, visible: Array<boolean|null>}} suggestion  per frame
 * @returns {Entry[]}
 */
export function prefillEntries(keyframes, suggestion) {
  const byFrame = new Map(keyframes.map((k) => [k.frame, k]));
  const entries = [];
  suggestion.xy.forEach((xy, f) => {
    const existing = byFrame.get(f);
    if (!xy || (existing && HAND_SOURCES.includes(sourceOf(existing)))) return;
    const visible = suggestion.visible[f] !== false;
    entries.push({ frame: f, x: xy[0], y: xy[1], visible, source: "prefilled" });
  });
  return entries;
}

/**
 * Epipolar lines in this view of one point at one frame, one per labelled view.
 * @param {Array<{serial: string, F: number[][], xy: Array<Array<number[]|null>>}>} epipolar
 * @param {number} point @param {number} frame @returns {EpipolarLine[]}
 */
export function epipolarLines(epipolar, point, frame) {
  const lines = [];
  for (const view of epipolar || []) {
    const p = view.xy && view.xy[point] ? view.xy[point][frame] : null;
    if (!p) continue;
    const [a, b, c] = view.F.map((row) => row[0] * p[0] + row[1] * p[1] + row[2]);
    const norm = Math.hypot(a, b);
    if (!(norm > 0)) continue;
    lines.push({ serial: view.serial, a: a / norm, b: b / norm, c: c / norm });
  }
  return lines;
}

/**
 * The part of a line inside the image [0, width] x [0, height], or null when it misses.
 * @param {{a: number, b: number, c: number}} line @param {number} width @param {number} height
 * @returns {number[][]|null} [[x0, y0], [x1, y1]] image px
 */
export function clipLine({ a, b, c }, width, height) {
  const hits = [];
  const inside = (x, y) => x >= -1e-9 && x <= width + 1e-9 && y >= -1e-9 && y <= height + 1e-9;
  if (Math.abs(b) > 1e-12) {
    for (const x of [0, width]) hits.push([x, -(a * x + c) / b]);
  }
  if (Math.abs(a) > 1e-12) {
    for (const y of [0, height]) hits.push([-(b * y + c) / a, y]);
  }
  const kept = hits.filter(([x, y]) => inside(x, y));
  if (kept.length < 2) return null;
  // The two hits farthest apart (a line through a corner hits it twice).
  let best = null;
  for (let i = 0; i < kept.length; i++) {
    for (let j = i + 1; j < kept.length; j++) {
      const d = Math.hypot(kept[i][0] - kept[j][0], kept[i][1] - kept[j][1]);
      if (!best || d > best.d) best = { d, ends: [kept[i], kept[j]] };
    }
  }
  return best && best.d > 0 ? best.ends : null;
}

/**
 * The assistance of one page: proposals shown as ghosts, the task's suggestions, the epipolar
 * lines' toggle, re-tracks after corrections, and a status line for the worker.
 */
export class Assist {
  /**
   * @param {Object} o
   * @param {import("./core/store.js").AnnotationStore} o.store
   * @param {{proposals: (body: object) => Promise<any>, suggestions: () => Promise<any>}} o.api
   * @param {() => boolean} o.editable  whether the page may write now (edit mode, not locked)
   * @param {() => {frame: number, active: number}} o.where  the editor's frame and point
   * @param {() => void} o.onChange  ghosts, lines or status changed: redraw
   * @param {number} [o.retrackDelayMs]
   */
  constructor({ store, api, editable, where, onChange, retrackDelayMs = RETRACK_DELAY_MS }) {
    this.store = store;
    this.api = api;
    this.editable = editable;
    this.where = where;
    this.onChange = onChange;
    this.retrackDelayMs = retrackDelayMs;
    /** @type {null|{points: PointProposal[], counts: {tracked: number, total: number}}} */
    this.proposals = null;
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
    for (const p of points) {
      const keyframes = this.store.keyframes(p);
      const found = allPoints ? allSpans(keyframes) : spanAround(keyframes, frame);
      if (found.length) spans.set(p, found);
    }
    if (!spans.size) {
      this._say("warn", allPoints
        ? "Nothing to track: set a visible keyframe on each side of a stretch first."
        : "Tracking needs a visible keyframe set by you on each side of this frame, " +
          "at least 2 frames apart.");
      return false;
    }
    const all = [...spans.values()].flat();
    const body = {
      tracks: [...spans.keys()].map((p) => ({ point: p, keyframes: anchorRows(this.store.keyframes(p)) })),
      first_frame: Math.min(...all.map((s) => s[0])),
      last_frame: Math.max(...all.map((s) => s[1])),
    };
    this._tracking = true;
    this._say("busy", "Tracking…");
    try {
      const answer = await this.api.proposals(body);
      const shown = answer.points.filter((p) => spans.has(p.point)).map((p) => ({
        point: p.point, first: answer.first_frame, last: answer.last_frame,
        spans: spans.get(p.point), xy: p.xy, ok: p.ok,
      }));
      const counts = countTracked(shown);
      this.proposals = { points: shown, counts };
      this._say("info", `${trackedText(counts)} (cyan rings). Enter accepts, Esc discards.`);
      return true;
    } catch (err) {
      this._say("error", `Tracking failed: ${err && err.message ? err.message : err}`);
      return false;
    } finally {
      this._tracking = false;
    }
  }

  /** Writes the shown proposals as "tracked" keyframes. @returns {boolean} */
  accept() {
    if (!this.proposals || !this.editable()) return false;
    const { points, counts } = this.proposals;
    this.proposals = null;
    this._write(points.map((p) => [p.point, proposalEntries(this.store.keyframes(p.point), p)]),
      "accept tracking");
    this._say("ok", `Accepted: ${trackedText(counts)}.`);
    return true;
  }

  /** Drops the shown proposals. @returns {boolean} whether there were any */
  discard() {
    if (!this.proposals) return false;
    this.proposals = null;
    this._say("none", "");
    return true;
  }

  // ---- corrections ------------------------------------------------------------------------

  /** A keyframe set by hand inside a run of tracked keyframes re-tracks around it. */
  _onStoreChange(change) {
    if (this._writing || change.cause === "saved") return;
    const points = change.points || (change.point === null ? [] : [change.point]);
    this._dropStaleProposals(points);
    if (change.cause !== "edit") return;
    const corrected = new Map();
    for (const point of points) {
      for (const frame of [...change.created, ...change.updated]) {
        const k = this.store.keyframeAt(point, frame);
        if (!k || !HAND_SOURCES.includes(sourceOf(k))) continue;
        if (retrackSpans(this.store.keyframes(point), frame).length) corrected.set(point, frame);
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
      const spans = retrackSpans(keyframes, frame);
      if (spans.length) asked.set(point, { keyframes, spans });
    }
    if (!asked.size) return;
    const all = [...asked.values()].flatMap((a) => a.spans);
    const [first, last] = [Math.min(...all.map((s) => s[0])), Math.max(...all.map((s) => s[1]))];
    const editCount = this.store.editCount;
    this._inFlight += 1;
    let answer;
    try {
      answer = await this.api.proposals({
        tracks: [...asked].map(([point, a]) => ({ point, keyframes: anchorRows(a.keyframes) })),
        first_frame: first, last_frame: last,
      });
    } catch (err) {
      this._say("error", `Re-tracking failed: ${err && err.message ? err.message : err}`);
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
    const proposals = answer.points.filter((p) => asked.has(p.point)).map((found) => ({
      point: found.point, first: answer.first_frame, last: answer.last_frame,
      spans: asked.get(found.point).spans, xy: found.xy, ok: found.ok,
    }));
    this._write(proposals.map((p) => [p.point, proposalEntries(asked.get(p.point).keyframes, p)]),
      "re-track");
    const around = asked.size === 1
      ? "your correction" : `your corrections of ${asked.size} points`;
    this._say("ok", `Re-tracked frames ${first}-${last} around ${around}: ` +
      `${trackedText(countTracked(proposals))}.`);
  }

  // ---- suggestions ------------------------------------------------------------------------

  /** Reads the task's suggestions once (edit mode). */
  async loadSuggestions() {
    let answer;
    try {
      answer = await this.api.suggestions();
    } catch (err) {
      this.suggestNote = `No suggestions: ${err && err.message ? err.message : err}`;
      this.onChange();
      return;
    }
    this.epipolar = Array.isArray(answer.epipolar) ? answer.epipolar : [];
    if (answer.available) {
      for (const s of answer.points || []) this.suggestions.set(s.point, s);
      const n = Array.isArray(answer.views) ? answer.views.length : Number(answer.views) || 0;
      this.suggestNote = `Suggestions from ${n} other ${n === 1 ? "view" : "views"} ` +
        "(magenta ring): U uses them for this point, Shift+U for every point.";
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
      .map((p) => ({ point: p.point, frames: okFrames(p) }));
  }

  // ---- internals --------------------------------------------------------------------------

  /**
   * One store batch over every point written (one undo step); the store changes it causes are
   * not corrections.
   * @param {Array<[number, Entry[]]>} writes  [point, entries] @param {string} label
   */
  _write(writes, label) {
    this._writing = true;
    try {
      const groups = writes.filter(([, entries]) => entries.length)
        .map(([point, entries]) => ({ point, entries }));
      this.store.setTracks(groups, { label });
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

/** The frames inside a proposal's spans where it holds. @param {PointProposal} p */
/** A proposal's held positions in runs of consecutive frames (image px), for its path. */
function heldRuns(p) {
  const runs = [];
  let previous = null;
  for (const f of okFrames(p)) {
    if (previous === null || f !== previous + 1) runs.push([]);
    runs[runs.length - 1].push(p.xy[f - p.first]);
    previous = f;
  }
  return runs;
}

function okFrames(p) {
  const frames = [];
  for (const [a, b] of p.spans) {
    for (let f = a + 1; f < b; f++) if (p.ok[f - p.first] && p.xy[f - p.first]) frames.push(f);
  }
  return frames;
}
