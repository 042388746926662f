/**
 * The page's small DOM pieces: the point list, the banner, the save status and the loading bar.
 * They only display what they are told; app.js decides what.
 *
 * Each point list row shows the point's key (core/tools.js jointKeys) and two view toggles,
 * hide and lock, whose clicks go to the `onToggle` callback.
 */

/**
 * Small icons of the hide and lock toggles (16 x 16 SVG, drawn in currentColor); a hidden
 * point's eye is struck through (style.css).
 */
const EYE_ICON = '<svg viewBox="0 0 16 16" aria-hidden="true"><path d="M1 8c2-3.5 4.5-5 7-5s5 ' +
  '1.5 7 5c-2 3.5-4.5 5-7 5S3 11.5 1 8z" fill="none" stroke="currentColor" stroke-width="1.5"/>' +
  '<circle cx="8" cy="8" r="2.2" fill="currentColor"/>' +
  '<line class="slash" x1="2" y1="14" x2="14" y2="2" stroke="currentColor" stroke-width="1.8"/>' +
  "</svg>";
const LOCK_ICON = '<svg viewBox="0 0 16 16" aria-hidden="true"><rect x="3" y="7" width="10" ' +
  'height="7" rx="1" fill="currentColor"/><path d="M5 7V5a3 3 0 0 1 6 0v2" fill="none" ' +
  'stroke="currentColor" stroke-width="1.5"/></svg>';

/** "Shift+3" -> "⇧3" (the list is narrow; the title says it in full). @param {string} key */
function shortKey(key) {
  return key.replace("Shift+", "\u21e7");
}

import { jointKeys } from "./core/tools.js";
import { escapeHtml, pointLabels } from "./instructions.js";

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
   * @param {{kind: string, point_names: string[], point_colors: string[]}} task
   * @param {(point: number) => void} onSelect
   * @param {(point: number, what: "hide"|"lock") => void} [onToggle]
   */
  constructor(container, task, onSelect, onToggle = () => {}) {
    const keys = jointKeys(task.kind, task.point_names.length);
    this._labels = pointLabels(task);
    container.innerHTML = task.point_names.map((_, i) => {
      const label = escapeHtml(this._labels[i]);
      const key = keys[i] ? `<kbd class="point-key" title="Key ${keys[i]}">` +
        `${escapeHtml(shortKey(keys[i]))}</kbd>` : "<span></span>";
      return `<li class="point-item" data-point="${i}">` +
        `<button type="button" class="point-row" data-point="${i}" data-state="unplaced">` +
        `<span class="swatch" style="background:${escapeHtml(task.point_colors[i])}"></span>` +
        `<span class="point-name">${label}</span>${key}` +
        `<span class="point-state">${STATE_TEXT.unplaced}</span></button>` +
        `<button type="button" class="point-toggle point-hide" data-toggle="hide" ` +
        `aria-pressed="false" title="Hide ${label} (H)">${EYE_ICON}</button>` +
        `<button type="button" class="point-toggle point-lock" data-toggle="lock" ` +
        `aria-pressed="false" title="Lock ${label}: no click or drag moves it">${LOCK_ICON}` +
        "</button></li>";
    }).join("");
    /** @type {HTMLButtonElement[]} */
    this.rows = [...container.querySelectorAll(".point-row")];
    /** @type {HTMLLIElement[]} */
    this.items = [...container.querySelectorAll(".point-item")];
    this._states = this.rows.map(() => "");
    this._keyed = this.rows.map(() => false);
    this._active = -1;
    /** Hide/lock clicks: (point, "hide"|"lock"); wiring.js may set it later. */
    this.onToggle = onToggle;
    container.addEventListener("click", (e) => {
      const target = e.target instanceof Element ? e.target : null;
      const toggle = target ? target.closest(".point-toggle") : null;
      const row = target ? target.closest(".point-row") : null;
      const item = target ? target.closest(".point-item") : null;
      if (toggle instanceof HTMLElement && item instanceof HTMLElement) {
        const what = toggle.dataset.toggle === "lock" ? "lock" : "hide";
        this.onToggle(Number(item.dataset.point), what);
        toggle.blur();
      } else if (row instanceof HTMLElement) {
        onSelect(Number(row.dataset.point));
        row.blur();  // keys (Space, arrows) belong to the editor, not to a focused button
      }
    });
  }

  /**
   * Shows which points are hidden and locked.
   * @param {ReadonlySet<number>} hidden @param {ReadonlySet<number>} locked
   */
  setViewState(hidden, locked) {
    this.items.forEach((item, p) => {
      const isHidden = hidden.has(p);
      const isLocked = locked.has(p);
      if (item.dataset.hidden === String(isHidden) && item.dataset.locked === String(isLocked)) {
        return;
      }
      item.dataset.hidden = String(isHidden);
      item.dataset.locked = String(isLocked);
      const [hide, lock] = item.querySelectorAll(".point-toggle");
      hide.setAttribute("aria-pressed", String(isHidden));
      lock.setAttribute("aria-pressed", String(isLocked));
      hide.title = `${isHidden ? "Show" : "Hide"} ${this._labels[p]} (H)`;
      lock.title = isLocked ? `Unlock ${this._labels[p]}`
        : `Lock ${this._labels[p]}: no click or drag moves it`;
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
      const text = STATE_TEXT[state] + (keyed && state === "occluded" ? " (keyframe)" : "");
      row.querySelector(".point-state").textContent = text;
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
 * @param {import("./core/loader.js").LoadProgress} p
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
