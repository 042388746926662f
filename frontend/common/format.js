/** Numbers for people, as every page writes them: money and durations (no DOM). */

/** What a page shows where a value is unknown. */
export const NONE = "–";

/** @param {unknown} value @returns {value is number} */
export function isNumber(value) {
  return typeof value === "number" && Number.isFinite(value);
}

/**
 * US dollars with two decimals; the API writes amounts as decimal strings ("1.5", MTurk's
 * "0.50"). A dash where unknown.
 * @param {string|number|null|undefined} amount
 */
export function dollars(amount) {
  const value = Number(amount);
  if (amount === null || amount === undefined || amount === "" || !Number.isFinite(value)) {
    return NONE;
  }
  return `${value < 0 ? "-" : ""}$${Math.abs(value).toFixed(2)}`;
}

/**
 * A duration for people, a dash where unknown. To the second (how long work took): "45 s",
 * "2 min 05 s", "1 h 02 min". To the minute (a time allotted, where a round figure reads
 * better): "45 s", "30 min", "1 h", "1 h 30 min".
 * @param {number|null|undefined} value  seconds
 * @param {"second"|"minute"} [to]
 */
export function duration(value, to = "second") {
  if (!isNumber(value)) return NONE;
  if (to === "minute") return toMinute(value);
  const s = Math.round(value);
  if (s < 60) return `${s} s`;
  if (s < 3600) return `${Math.floor(s / 60)} min ${String(s % 60).padStart(2, "0")} s`;
  return `${Math.floor(s / 3600)} h ${String(Math.floor((s % 3600) / 60)).padStart(2, "0")} min`;
}

/** @param {number} seconds */
function toMinute(seconds) {
  if (seconds < 60) return `${Math.round(seconds)} s`;
  const minutes = Math.round(seconds / 60);
  if (minutes < 60) return `${minutes} min`;
  const h = Math.floor(minutes / 60), m = minutes % 60;
  return m ? `${h} h ${m} min` : `${h} h`;
}
