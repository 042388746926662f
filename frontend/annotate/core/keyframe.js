/**
 * One stored keyframe of the annotation store (store.js): its value checked, rounded to the
 * 0.01 px grid and clamped into the image, and its saved row [frame, x, y, visible01] or
 * [frame, x, y, visible01, source].
 *
 * Positions are image pixels, 0 <= x < width, 0 <= y < height; 0.01 px is the precision of the
 * autosave payload, so a keyframe written as a row and read back is the same keyframe.
 *
 * Pure: no DOM, no state.
 */

import { checkSource } from "./edits.js";

/** Stored coordinate precision, image px. */
export const POSITION_STEP_PX = 0.01;

/**
 * @typedef {import("./edits.js").KeyframeSource} KeyframeSource
 * @typedef {import("./interpolate.js").Keyframe & {source: KeyframeSource}} Keyframe
 * @typedef {{width: number, height: number}} ImageSize  image px
 */

/** Rounds to the 0.01 px grid (idempotent: a rounded value rounds to itself). @param {number} v */
function quantize(v) {
  return Math.round(v * 100) / 100;
}

/**
 * Throws unless `value` is an integer index in 0..count-1.
 * @param {string} name  "point" or "frame"  @param {any} value  @param {number} count
 */
export function checkIndex(name, value, count) {
  if (!Number.isInteger(value) || value < 0 || value >= count) {
    throw new RangeError(`${name} must be an integer in 0..${count - 1}, got ${value}`);
  }
}

/**
 * Clamps an image position into the image (0 <= x < width) on the stored 0.01 px grid.
 * @param {number} x @param {number} y @param {ImageSize} image
 * @returns {{x: number, y: number}}
 */
export function clampToImage(x, y, { width, height }) {
  // The largest stored coordinate is size - 0.01, so that x < width holds after rounding.
  const clamp = (/** @type {number} */ v, /** @type {number} */ size) =>
    Math.min(Math.max(quantize(v), 0), quantize(size - POSITION_STEP_PX));
  return { x: clamp(x, width), y: clamp(y, height) };
}

/**
 * A frozen keyframe: both coordinates null (occluded, never placed) or finite numbers, which
 * are rounded and clamped into the image.
 * @param {number} frame @param {{x: any, y: any, visible: any}} value
 * @param {KeyframeSource} source @param {ImageSize} image @returns {Keyframe}
 */
export function makeKeyframe(frame, { x, y, visible }, source, image) {
  if (typeof visible !== "boolean") {
    throw new TypeError(`visible must be a boolean, got ${visible}`);
  }
  if (x === null && y === null) {
    if (visible) throw new TypeError(`frame ${frame}: a visible keyframe needs a position`);
    return Object.freeze({ frame, x: null, y: null, visible, source });
  }
  if (!Number.isFinite(x) || !Number.isFinite(y)) {
    const got = `${x}, ${y}`;
    const rule = "x and y must be finite numbers or both null";
    throw new TypeError(`frame ${frame}: ${rule}, got ${got}`);
  }
  return Object.freeze({ frame, ...clampToImage(x, y, image), visible, source });
}

/**
 * The saved row of a keyframe: [frame, x, y, visible01] for a "placed" keyframe (so payloads
 * without suggestions are as before), [frame, x, y, visible01, source] otherwise.
 * @param {Keyframe} k @returns {any[]}
 */
export function keyframeToRow(k) {
  const row = [k.frame, k.x, k.y, k.visible ? 1 : 0];
  if (k.source !== "placed") row.push(k.source);
  return row;
}

/**
 * @param {number} point
 * @param {any} row [frame, x, y, visible01] or [frame, x, y, visible01, source]
 * @param {ImageSize & {numFrames: number}} clip
 * @returns {Keyframe}
 */
function keyframeFromRow(point, row, clip) {
  if (!Array.isArray(row) || (row.length !== 4 && row.length !== 5)) {
    const got = JSON.stringify(row);
    const shape = "[frame, x, y, visible01] or [frame, x, y, visible01, source]";
    throw new TypeError(`point ${point}: keyframe must be ${shape}, got ${got}`);
  }
  const [frame, x, y, visible, source = "placed"] = row;
  checkIndex("frame", frame, clip.numFrames);
  if (visible !== 0 && visible !== 1 && visible !== true && visible !== false) {
    throw new TypeError(`point ${point}, frame ${frame}: visible must be 0 or 1, got ${visible}`);
  }
  checkSource(source, `point ${point}, frame ${frame}`);
  return makeKeyframe(frame, { x, y, visible: Boolean(visible) }, source, clip);
}

/**
 * A point's track from its saved rows: checked, sorted by frame, one keyframe per frame.
 * @param {number} point @param {any} rows  see keyframeToRow
 * @param {ImageSize & {numFrames: number}} clip
 * @returns {Keyframe[]}
 */
export function trackFromRows(point, rows, clip) {
  if (!Array.isArray(rows)) {
    throw new TypeError(`point ${point}: keyframes must be an array`);
  }
  const keyframes = rows.map((row) => keyframeFromRow(point, row, clip));
  keyframes.sort((a, b) => a.frame - b.frame);
  keyframes.forEach((k, i) => {
    if (i > 0 && keyframes[i - 1].frame === k.frame) {
      throw new RangeError(`point ${point}: two keyframes at frame ${k.frame}`);
    }
  });
  return keyframes;
}
