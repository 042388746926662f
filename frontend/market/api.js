/**
 * The portal API (/api/portal). The worker's signed token travels as a bearer header and is
 * kept in sessionStorage, never in a cookie.
 */

import { ApiError, BearerClient } from "../common/api.js";

export class PortalApi extends BearerClient {
  /** @param {Storage} storage */
  constructor(storage) {
    super(storage, "dexlabel.portal.token", "/api/portal",
      { login: "/login", logout: "/logout" });
  }

  /** @param {string} invite @param {string} email @param {string} password */
  register(invite, email, password) {
    return this.request("POST", "/register", { invite, email, password });
  }

  me() { return this.request("GET", "/me"); }
  /** The HITs to take, with the ones this worker accepted or submitted marked. */
  hits() { return this.request("GET", "/hits?mine=true"); }
  /** @param {string} hitId */
  preview(hitId) { return this.request("GET", `/hits/${encodeURIComponent(hitId)}`); }
  /** @param {string} hitId */
  accept(hitId) { return this.request("POST", `/hits/${encodeURIComponent(hitId)}/accept`); }
  assignments() { return this.request("GET", "/assignments"); }
  /** @param {string} id */
  assignment(id) { return this.request("GET", `/assignments/${encodeURIComponent(id)}`); }
  /** @param {string} id */
  giveBack(id) { return this.request("POST", `/assignments/${encodeURIComponent(id)}/return`); }

  /**
   * Hands in the work of a page that completes back to the portal (a team HIT): the
   * marketplace's ExternalQuestion form, as an MTurk page posts it itself, so the assignment
   * is Submitted there (for the requester, and in this worker's list).
   * @param {string} id  the assignment  @param {string} result  the page's "submitted:{version}"
   */
  async handIn(id, result) {
    const resp = await fetch("/mturk/externalSubmit", { method: "POST", credentials: "omit",
      body: new URLSearchParams({ assignmentId: id, result }) });
    if (!resp.ok) {
      throw new ApiError(resp.status, { detail: `the marketplace did not take assignment ${id} `
        + `(${resp.status}); your work is saved: open the HIT again and submit` });
    }
  }
}
