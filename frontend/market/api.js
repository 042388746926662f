/**
 * The portal API (/api/portal). The worker's signed token travels as a bearer header and is
 * kept in sessionStorage, never in a cookie.
 */

const TOKEN_KEY = "dexlabel.portal.token";

export class ApiError extends Error {
  /** @param {number} status @param {any} data */
  constructor(status, data) {
    const detail = data && data.detail;
    super(typeof detail === "string" ? detail : `request failed (${status})`);
    this.status = status;
  }
}

export class PortalApi {
  /** @param {Storage} storage */
  constructor(storage) {
    this.storage = storage;
    /** @type {string|null} */
    this.token = storage.getItem(TOKEN_KEY);
  }

  /** @param {string|null} token */
  setToken(token) {
    this.token = token;
    if (token) this.storage.setItem(TOKEN_KEY, token);
    else this.storage.removeItem(TOKEN_KEY);
  }

  /**
   * @param {string} method
   * @param {string} path   below /api/portal
   * @param {object} [body]
   */
  async request(method, path, body) {
    /** @type {Record<string, string>} */
    const headers = { Accept: "application/json" };
    if (body !== undefined) headers["Content-Type"] = "application/json";
    if (this.token) headers.Authorization = `Bearer ${this.token}`;
    /** @type {RequestInit} */
    const init = { method, headers, credentials: "omit", cache: "no-store" };
    if (body !== undefined) init.body = JSON.stringify(body);
    const resp = await fetch(`/api/portal${path}`, init);
    let data = null;
    try {
      data = await resp.json();
    } catch {
      data = null;
    }
    if (resp.status === 401 && this.token) this.setToken(null);
    if (!resp.ok) throw new ApiError(resp.status, data);
    return data;
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

  me() { return this.request("GET", "/me"); }
  hits() { return this.request("GET", "/hits"); }
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
