/**
 * How a submitted page hands the assignment back to its crowd: the start reply's `completion`
 * ({kind, url}, chosen by the provider that published the HIT) turned into one step for the
 * page to take. Pure: no DOM, no window; submit.js carries the step out.
 *
 *   form_post  post the completion form (MTurk's externalSubmit; an empty url: to the
 *              `turkSubmitTo` the address carries)
 *   redirect   send the worker's browser to the url (Prolific's completion link): the whole
 *              window when the page is framed, where the frame allows it
 *   portal     back to the portal's list: tell the portal framing the page, or open the url
 *              when the page stands alone
 * No completion (a HIT published elsewhere, a direct link): today's externalSubmit form when
 * the address has `turkSubmitTo`, else nothing.
 */

/** @typedef {{kind: "form_post" | "redirect" | "portal", url: string}} Completion */

/**
 * @typedef {{action: "form", url: string, assignmentId: string}
 *   | {action: "top" | "navigate", url: string, handIn?: HandIn}
 *   | {action: "parent", url: string, origin: string, handIn?: HandIn}
 *   | {action: "none"}} CompletionStep
 */

/**
 * The marketplace form a portal completion posts in the background before going back to the
 * portal (the team's HITs are the built-in marketplace's: its record of the assignment must
 * say submitted, as MTurk's form post would make it, for crowd sync to collect the work).
 * @typedef {{url: string, assignmentId: string}} HandIn
 */

/** The message a framed page posts to the portal when its work is submitted. */
export const SUBMITTED_MESSAGE = "dexlabel:submitted";

const KINDS = new Set(["form_post", "redirect", "portal"]);
// The fragment's names for the completion (kept beside the token, so a reload keeps it).
const KIND_KEY = "completion";
const URL_KEY = "completion_url";
// Only to check a url's form: a relative url (the portal's "/market/#/hits") is resolved
// against the page's own address when the step is taken.
const CHECK_BASE = "http://page.invalid/";

/**
 * The url resolved against the page's own address when it is one the page may go to (http or
 * https); null otherwise (a `javascript:` url, garbage).
 * @param {string} url @param {string} base
 * @returns {URL | null}
 */
function webUrl(url, base) {
  try {
    const resolved = new URL(url, base);
    return resolved.protocol === "https:" || resolved.protocol === "http:" ? resolved : null;
  } catch {
    return null;
  }
}

/**
 * A completion the page can follow, or null: an unknown kind, or a redirect or portal without
 * a web address, is ignored (the page then completes as it always has).
 * @param {any} value  the start reply's `completion`, or one read from the fragment
 * @returns {Completion | null}
 */
export function checkedCompletion(value) {
  if (!value || typeof value !== "object" || !KINDS.has(value.kind)) return null;
  const url = typeof value.url === "string" ? value.url : "";
  if (value.kind !== "form_post" && !url) return null;
  return url && !webUrl(url, CHECK_BASE) ? null : { kind: value.kind, url };
}

/**
 * The completion kept in the address's fragment (see completionEntries).
 * @param {URLSearchParams} fragment
 * @returns {Completion | null}
 */
export function completionFromFragment(fragment) {
  const kind = fragment.get(KIND_KEY);
  return kind ? checkedCompletion({ kind, url: fragment.get(URL_KEY) || "" }) : null;
}

/**
 * The fragment's entries that keep a completion across a reload (none for null).
 * @param {Completion | null} completion
 * @returns {[string, string][]}
 */
export function completionEntries(completion) {
  if (!completion) return [];
  return completion.url
    ? [[KIND_KEY, completion.kind], [URL_KEY, completion.url]]
    : [[KIND_KEY, completion.kind]];
}

/**
 * The step that completes a submitted assignment.
 * @param {{completion: Completion | null, turkSubmitTo: string | null,
 *   assignmentId: string | null, preview: boolean}} params  the page's (api.js PageParams)
 * @param {{framed: boolean, base: string}} where  framed: the page runs inside a frame
 *   (window.top !== window); base: the page's address
 * @returns {CompletionStep}
 */
export function completionStep(params, where) {
  const { completion, turkSubmitTo, assignmentId, preview } = params;
  if (preview) return { action: "none" };
  const kind = completion ? completion.kind : "form_post";
  if (kind === "form_post") {
    const url = completion && completion.url
      ? completion.url
      : turkSubmitTo ? `${turkSubmitTo.replace(/\/+$/, "")}/mturk/externalSubmit` : "";
    return url && assignmentId ? { action: "form", url, assignmentId } : { action: "none" };
  }
  const target = completion && webUrl(completion.url, where.base);
  if (!target) return { action: "none" };
  if (kind === "redirect") {
    return { action: where.framed ? "top" : "navigate", url: target.href };
  }
  const handIn = turkSubmitTo && assignmentId
    ? { handIn: { url: `${turkSubmitTo.replace(/\/+$/, "")}/mturk/externalSubmit`, assignmentId } }
    : {};
  if (!where.framed) return { action: "navigate", url: target.href, ...handIn };
  return { action: "parent", url: target.href, origin: target.origin, ...handIn };
}
