/**
 * Active working time of one assignment, for pay and QC: time counts while the tab is visible
 * and the worker has done something (pointer, key, wheel) in the last IDLE_AFTER_MS. A worker who
 * leaves the tab open over lunch is not paid for lunch. No DOM access; the page feeds it events.
 */

/** Without input for this long (ms), the clock stops until the next input. */
export const IDLE_AFTER_MS = 120000;

export class WorkClock {
  /**
   * @param {{baseSeconds?: number, now?: () => number, idleAfterMs?: number}} [options]
   *   baseSeconds: time already recorded by the server; now: a clock in ms
   */
  constructor({ baseSeconds = 0, now = () => performance.now(),
    idleAfterMs = IDLE_AFTER_MS } = {}) {
    this._now = now;
    this._idleAfterMs = idleAfterMs;
    this._totalMs = Math.max(0, baseSeconds) * 1000;
    const t = now();
    this._mark = t;
    this._lastActivity = t;
    this._visible = true;
  }

  /** Adds the active time since the last mark. @param {number} t */
  _advance(t) {
    if (this._visible) {
      const activeUntil = Math.min(t, this._lastActivity + this._idleAfterMs);
      this._totalMs += Math.max(0, activeUntil - this._mark);
    }
    this._mark = t;
  }

  /** The worker did something (call on input events). */
  activity() {
    const t = this._now();
    this._advance(t);
    this._lastActivity = t;
  }

  /** @param {boolean} visible  document.visibilityState === "visible" */
  setVisible(visible) {
    const t = this._now();
    this._advance(t);
    this._visible = visible;
    if (visible) this._lastActivity = t;
  }

  /** Total active time, seconds. */
  seconds() {
    this._advance(this._now());
    return Math.round(this._totalMs) / 1000;
  }
}
