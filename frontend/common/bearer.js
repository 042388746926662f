/**
 * A JSON client that carries a signed bearer token, kept in sessionStorage (never a cookie).
 * The admin page and the worker portal each extend it with their own endpoints.
 */

export class ApiError extends Error {
  /** @param {number} status @param {any} data */
  constructor(status, data) {
    const detail = data && data.detail;
    super(typeof detail === "string" ? detail : `request failed (${status})`);
    this.status = status;
  }
}

export class BearerClient {
  /**
   * @param {Storage} storage
   * @param {string} tokenKey  where the token is kept in storage
   * @param {string} base      URL prefix of every path, e.g. "/api"
   */
  constructor(storage, tokenKey, base) {
    this.storage = storage;
    this.tokenKey = tokenKey;
    this.base = base;
    /** @type {string|null} */
    this.token = storage.getItem(tokenKey);
  }

  /** @param {string|null} token */
  setToken(token) {
    this.token = token;
    if (token) this.storage.setItem(this.tokenKey, token);
    else this.storage.removeItem(this.tokenKey);
  }

  /**
   * The raw reply of a request; an ApiError with the API's detail when it fails (a 401 also
   * forgets the token).
   * @param {string} method
   * @param {string} path   below the base
   * @param {object} [body]
   * @param {string} [accept]
   */
  async send(method, path, body, accept = "application/json") {
    /** @type {Record<string, string>} */
    const headers = { Accept: accept };
    if (body !== undefined) headers["Content-Type"] = "application/json";
    if (this.token) headers.Authorization = `Bearer ${this.token}`;
    /** @type {RequestInit} */
    const init = { method, headers, credentials: "omit", cache: "no-store" };
    if (body !== undefined) init.body = JSON.stringify(body);
    const resp = await fetch(`${this.base}${path}`, init);
    if (resp.status === 401 && this.token) this.setToken(null);
    if (!resp.ok) {
      let data = null;
      try {
        data = await resp.json();
      } catch {
        data = null;
      }
      throw new ApiError(resp.status, data);
    }
    return resp;
  }

  /**
   * A JSON request; the reply's body (null when empty).
   * @param {string} method @param {string} path @param {object} [body]
   */
  async request(method, path, body) {
    const resp = await this.send(method, path, body);
    const text = await resp.text();
    return text ? JSON.parse(text) : null;
  }
}
