/**
 * The portal API (/api/portal). The worker's signed token travels as a bearer header and is
 * kept in sessionStorage, never in a cookie.
 */

import { BearerClient } from "../common/api.js";

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

}
