/**
 * The page's small DOM pieces: the point list, the banner, the save status and the loading bar.
 * They only display what they are told; app.js decides what.
 */

import { displayName, escapeHtml } from "./instructions.js";

/** What the point list says about a point in the current frame. */
export const STATE_TEXT = {
  keyframe: "keyframe",
  interpolated: "interpolated",
  occluded: "occluded",
  unplaced: "not placed",
};

/**
 * The list's state of a point value. @param {import("./core/interpolate.js").DenseValue} v
 * @returns {"keyframe"|"interpolated"|"occluded"|"unplaced"}
 */
export function pointState(v) {
  if (v.state === "unplaced") return "unplaced";
  if (!v.visible) return "occluded";
  return v.state;
}

export class PointList {
  /**
   * @param {HTMLElement} container
   * @param {{point_names: string[], point_colors: string[]}} task
   * @param {(point: number) => void} onSelect
   */
  constructor(container, task, onSelect) {
    container.innerHTML = task.point_names.map((name, i) =>
      `<li><button type="button" class="point-row" data-point="${i}" data-state="unplaced">` +
      `<span class="swatch" style="background:${escapeHtml(task.point_colors[i])}"></span>` +
      `<span class="point-name">${i} ${escapeHtml(displayName(name))}</span>` +
      `<span class="point-state">${STATE_TEXT.unplaced}</span></button></li>`).join("");
    /** @type {HTMLButtonElement[]} */
    this.rows = [...container.querySelectorAll(".point-row")];
    this._states = this.rows.map(() => "");
    this._keyed = this.rows.map(() => false);
    this._active = -1;
    container.addEventListener("click", (e) => {
      const row = e.target instanceof Element ? e.target.closest(".point-row") : null;
      if (!(row instanceof HTMLElement)) return;
      onSelect(Number(row.dataset.point));
      row.blur();  // keys (Space, arrows) belong to the editor, not to a focused button
    });
  }

  /**
   * Shows each point's state in this frame; touches only rows that changed.
   * @param {import("./core/interpolate.js").DenseValue[]} values @param {number} active
   */
  update(values, active) {
    values.forEach((v, i) => {
      const state = pointState(v);
      const keyed = v.state === "keyframe";
      if (state === this._states[i] && keyed === this._keyed[i]) return;
      const row = this.rows[i];
      row.dataset.state = state;
      row.classList.toggle("keyed", keyed);
      row.lastElementChild.textContent = STATE_TEXT[state] + (keyed && state === "occluded"
        ? " (keyframe)" : "");
      this._states[i] = state;
      this._keyed[i] = keyed;
    });
    if (active !== this._active) {
      if (this.rows[this._active]) this.rows[this._active].classList.remove("active");
      this.rows[active].classList.add("active");
      this.rows[active].scrollIntoView({ block: "nearest" });
      this._active = active;
    }
  }
}

/**
 * Shows (or, with an empty message, hides) the page banner.
 * @param {HTMLElement} el
 * @param {"info"|"warn"|"error"|"ok"} kind
 * @param {string} message
 * @param {HTMLElement} [extra]  e.g. a button
 */
export function showBanner(el, kind, message, extra) {
  el.hidden = !message;
  el.dataset.kind = kind;
  el.textContent = message;
  if (extra) el.append(" ", extra);
}

/**
 * @param {HTMLElement} el
 * @param {{state: string, message: string}} status  from AutoSaver
 */
export function showSaveStatus(el, status) {
  el.dataset.state = status.state;
  el.textContent = status.message;
}

/**
 * @param {HTMLElement} overlay  the loading overlay (holds a <progress> and a text line)
 * @param {import("./loader.js").LoadProgress} p
 */
export function showLoadProgress(overlay, p) {
  const bar = overlay.querySelector("progress");
  const text = overlay.querySelector(".loading-text");
  const fraction = p.totalBytes > 0
    ? 0.8 * (p.receivedBytes / p.totalBytes) + 0.2 * (p.numFrames ? p.decoded / p.numFrames : 0)
    : (p.numFrames ? p.decoded / p.numFrames : 0);
  bar.value = Math.min(1, fraction);
  const mb = (p.receivedBytes / 1e6).toFixed(1);
  const of = p.totalBytes ? ` of ${(p.totalBytes / 1e6).toFixed(1)}` : "";
  const frames = p.numFrames ? `, ${p.decoded} of ${p.numFrames} frames ready` : "";
  text.textContent = `Loading frames: ${mb}${of} MB${frames}`;
}
