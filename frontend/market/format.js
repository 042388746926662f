/** Pure formatting and routing helpers of the portal page (no DOM). */

/** @param {string} amount  USD as MTurk writes it ("0.50") */
export function money(amount) {
  return `$${Number(amount).toFixed(2)}`;
}

/**
 * A duration for people: "45 s", "20 min", "1 h 30 min".
 * @param {number} seconds
 */
export function duration(seconds) {
  if (seconds < 60) return `${Math.round(seconds)} s`;
  const minutes = Math.round(seconds / 60);
  if (minutes < 60) return `${minutes} min`;
  const h = Math.floor(minutes / 60), m = minutes % 60;
  return m ? `${h} h ${m} min` : `${h} h`;
}

/**
 * The page's place from its hash: #/hits, #/hits/<HITId>, #/work/<AssignmentId>, #/earnings.
 * @param {string} hash
 * @returns {{view: "hits"|"preview"|"work"|"earnings", id: string|null}}
 */
export function parseRoute(hash) {
  const [, view = "", id = ""] = hash.replace(/^#/, "").split("/");
  if (view === "hits" && id) return { view: "preview", id: decodeURIComponent(id) };
  if (view === "work" && id) return { view: "work", id: decodeURIComponent(id) };
  if (view === "earnings") return { view: "earnings", id: null };
  return { view: "hits", id: null };
}
