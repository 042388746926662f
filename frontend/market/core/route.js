/** The portal page's routes (no DOM). */

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

/**
 * The invite token of a registration link: from the fragment (``#invite=...``, which the
 * browser never sends to a server), or from the query of a link made before invites moved
 * there (``?invite=...``); "" when there is none.
 * @param {string} hash
 * @param {string} search
 * @returns {string}
 */
export function inviteOf(hash, search) {
  const fragment = new URLSearchParams(hash.replace(/^#/, "")).get("invite");
  return fragment || new URLSearchParams(search).get("invite") || "";
}
