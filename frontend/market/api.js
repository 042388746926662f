/**
 * The portal API (/api/portal). The worker's signed token travels as a bearer header and is
 * kept in sessionStorage, never in a cookie.
 */

import { ApiError, BearerClient } from "../common/bearer.js";

export { ApiError };

export class PortalApi extends BearerClient {
  /** @param {Storage} storage */
  constructor(storage) {
    super(storage, "dexlabel.portal.token", "/api/portal");
  }

  /** @param {string} email @param {string} password */
  async login(email, password) {
    const data = await this.request("POST", "/login", { email, password });
    this.setToken(data.access_token);
    return data;
  }

  /** @param {string} invite @param {string} email @param {string} password */
  register(invite, email, password) {
    return this.request("POST", "/register", { invite, email, password });
  }

  /** Revoke every token of this account on the server, then forget it here (also when the
   * server cannot be reached: signing out never fails on this page). */
  async logout() {
    try {
      if (this.token) await this.request("POST", "/logout");
    } finally {
      this.setToken(null);
    }
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
