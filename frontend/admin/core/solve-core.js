/**
 * The DOM-free core of solve review: which frame request goes out next, where a frame sits on
 * the slider, and the layouts of the residual and comparison charts. Frames are 0-based
 * indices; chart coordinates are SVG user units with y down.
 */

/** Overlay styles the API draws (GET .../views/{v}.png?style=). */
export const OVERLAY_STYLES = ["solid", "blend", "wireframe"];

/**
 * Runs one load at a time and only ever the newest wish: while a load is in flight, asking
 * for another key replaces any key still waiting, so frames skipped over while dragging or
 * playing are never requested; a reply for a key that is no longer the newest is dropped.
 * @template T
 */
export class LatestLoader {
  /**
   * @param {(key: string) => Promise<T>} load
   * @param {(key: string, value: T) => void} show  called with the newest key's reply only
   * @param {(err: unknown) => void} [fail]
   */
  constructor(load, show, fail = () => {}) {
    this.load = load;
    this.show = show;
    this.fail = fail;
    /** @type {string|null} */ this.inFlight = null;
    /** @type {string|null} */ this.waiting = null;
    /** @type {string|null} */ this.newest = null;
    /** Keys whose load started, in order (what was actually asked of the server). */
    /** @type {string[]} */ this.started = [];
  }

  /** Ask for ``key``; resolves when nothing is in flight any more. @param {string} key */
  request(key) {
    this.newest = key;
    if (this.inFlight !== null) {
      // Asking again for what is on its way adds nothing; anything else waits, alone.
      this.waiting = key === this.inFlight ? null : key;
      return this.idle();
    }
    return this.#run(key);
  }

  /** Forget every wish: replies in flight are dropped. */
  cancel() {
    this.newest = null;
    this.waiting = null;
  }

  /** @returns {Promise<void>} */
  idle() {
    return this.current || Promise.resolve();
  }

  /** @param {string} key */
  #run(key) {
    this.inFlight = key;
    this.started.push(key);
    this.current = (async () => {
      try {
        const value = await this.load(key);
        if (key === this.newest) this.show(key, value);
      } catch (err) {
        if (key === this.newest) this.fail(err);
      } finally {
        this.inFlight = null;
        this.current = null;
      }
      const next = this.waiting;
      this.waiting = null;
      if (next !== null && next === this.newest) await this.#run(next);
    })();
    return this.current;
  }
}

/**
 * The frame ``delta`` steps from ``frame``, wrapping at the ends when ``wrap`` (playback).
 * @param {number} frame @param {number} delta @param {number} count  frames in the run
 * @param {boolean} [wrap]
 */
export function stepFrame(frame, delta, count, wrap = false) {
  if (count <= 0) return 0;
  const next = frame + delta;
  if (wrap) return ((next % count) + count) % count;
  return Math.min(Math.max(next, 0), count - 1);
}

/**
 * Where frame ``frame`` sits along the slider, 0..100 %.
 * @param {number} frame @param {number} count
 */
export function tickPercent(frame, count) {
  return count > 1 ? (100 * frame) / (count - 1) : 0;
}

/**
 * The overlay picture's path below /api.
 * @param {number} runId @param {number} frame @param {string} view  serial or index
 * @param {string} style @param {number|null} alpha  null: the style's own opacity
 */
export function overlayPath(runId, frame, view, style, alpha) {
  const query = new URLSearchParams({ style });
  if (alpha !== null) query.set("alpha", String(alpha));
  return `/solve-runs/${runId}/frames/${frame}/views/${encodeURIComponent(view)}.png?${query}`;
}

/** A round axis top at or above ``largest``: 1, 2, 5, 10, 20, ... @param {number} largest */
export function niceTop(largest) {
  const top = Math.max(largest, 1e-9);
  const scale = 10 ** Math.floor(Math.log10(top));
  for (const step of [1, 2, 5, 10]) if (step * scale >= top - 1e-9) return step * scale;
  return 10 * scale;
}

/**
 * Bars of one frame's reprojection error per joint (groups) and view (one bar each).
 * @param {Record<string, (number|null)[]>} errors  serial -> 21 values px (null: not observed)
 * @param {{width: number, height: number, left: number, bottom: number, top: number}} box
 * @returns {{max: number, bars: {x: number, y: number, w: number, h: number, view: number,
 *   joint: number, value: number}[], missing: number}}
 */
export function residualBars(errors, box) {
  const views = Object.values(errors);
  const joints = Math.max(0, ...views.map((v) => v.length));
  const values = views.flat().filter((v) => typeof v === "number" && Number.isFinite(v));
  const max = niceTop(Math.max(...values, 0) || 1);
  const plotW = box.width - box.left, plotH = box.height - box.top - box.bottom;
  const group = joints ? plotW / joints : plotW;
  const barW = (group * 0.8) / Math.max(views.length, 1);
  const bars = [];
  let missing = 0;
  for (let j = 0; j < joints; j += 1) {
    for (let v = 0; v < views.length; v += 1) {
      const value = views[v][j];
      if (typeof value !== "number" || !Number.isFinite(value)) {
        missing += 1;
        continue;
      }
      const h = (plotH * Math.min(value, max)) / max;
      bars.push({ x: box.left + group * j + group * 0.1 + barW * v, y: box.top + plotH - h,
        w: Math.max(barW - 0.5, 0.5), h, view: v, joint: j, value });
    }
  }
  return { max, bars, missing };
}

/**
 * Polylines of per-frame series on a shared y axis from 0.
 * @param {{name: string, values: (number|null)[]}[]} series
 * @param {{width: number, height: number, left: number, bottom: number, top: number,
 *   right?: number}} box
 * @returns {{max: number, lines: {name: string, points: [number, number][]}[],
 *   x: (frame: number) => number}}
 */
export function seriesLines(series, box) {
  const count = Math.max(0, ...series.map((s) => s.values.length));
  const finite = series.flatMap((s) => s.values).filter(
    (v) => typeof v === "number" && Number.isFinite(v));
  const max = niceTop(Math.max(...finite, 0) || 1);
  const plotW = box.width - box.left - (box.right ?? 0);
  const plotH = box.height - box.top - box.bottom;
  const x = (/** @type {number} */ f) => box.left + (count > 1 ? (plotW * f) / (count - 1) : 0);
  const lines = series.map((s) => ({
    name: s.name,
    points: /** @type {[number, number][]} */ (s.values.flatMap((v, f) =>
      typeof v === "number" && Number.isFinite(v)
        ? [[x(f), box.top + plotH - (plotH * Math.min(v, max)) / max]] : [])),
  }));
  return { max, lines, x };
}

/**
 * The settings to send with a re-run: each field parsed by its kind; an error naming the
 * first field that does not parse.
 * @param {Record<string, string>} kinds  GET /api/solve-settings kinds: bool, int or float
 * @param {Record<string, string|boolean>} edited  field -> input value (checkbox: boolean)
 * @returns {Record<string, number|boolean>}
 */
export function parseSettings(kinds, edited) {
  /** @type {Record<string, number|boolean>} */
  const out = {};
  for (const [name, value] of Object.entries(edited)) {
    if (kinds[name] === "bool") {
      out[name] = Boolean(value);
      continue;
    }
    const number = Number(value);
    if (String(value).trim() === "" || !Number.isFinite(number)) {
      throw new Error(`${name} must be a number, got "${value}"`);
    }
    if (kinds[name] === "int" && !Number.isInteger(number)) {
      throw new Error(`${name} must be a whole number, got "${value}"`);
    }
    out[name] = number;
  }
  return out;
}
