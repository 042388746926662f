/**
 * The pages' JSON client: one error for every refused or failed request, the request every
 * page sends (bearer header, no cookies, no cache), and a client that keeps its bearer token in
 * sessionStorage (never a cookie), which the admin page and the worker portal extend with their
 * own endpoints. The annotation page sends the same requests with its own token and timeout
 * (annotate/api.js). No DOM.
 */

/** An HTTP error answer; `status` is 0 when the network failed (offline, timeout). */
export class ApiError extends Error {
  /**
   * @param {number} status  HTTP status, 0 for a network failure
   * @param {{error?: string, detail?: unknown}|null} body  the server's JSON error, if any
   */
  constructor(status, body) {
    const detail = body && body.detail ? body.detail : `request failed (${status || "network"})`;
    super(typeof detail === "string" ? detail : JSON.stringify(detail));
    this.status = status;
    this.body = body || {};
    this.code = this.body.error || (status === 0 ? "network" : "http");
  }

  /** True when retrying later may succeed (offline, timeout, server overloaded). */
  get retryable() {
    return this.status === 0 || this.status === 408 || this.status === 429 || this.status >= 500;
  }
}

/**
 * The fetch options of one API request: JSON in and out, the token as a bearer header,
 * never a cookie, never a cached answer.
 * @param {string} method
 * @param {string|null} token
 * @param {object} [body]
 * @param {string} [accept]
 * @returns {RequestInit}
 */
export function requestInit(method, token, body, accept = "application/json") {
  /** @type {Record<string, string>} */
  const headers = { Accept: accept };
  if (token) headers.Authorization = `Bearer ${token}`;
  if (body !== undefined) headers["Content-Type"] = "application/json";
  /** @type {RequestInit} */
  const init = { method, headers, credentials: "omit", cache: "no-store" };
  if (body !== undefined) init.body = JSON.stringify(body);
  return init;
}

/**
 * A reply's JSON body, or null when it has none or it does not parse.
 * @param {{json: () => Promise<any>}} resp
 */
export async function jsonOrNull(resp) {
  try {
    return await resp.json();
  } catch {
    return null;
  }
}

export class BearerClient {
  /**
   * @param {Storage} storage
   * @param {string} tokenKey  where the token is kept in storage
   * @param {string} base      URL prefix of every path, e.g. "/api"
   * @param {{login: string, logout: string}} account  paths (below the base) that sign in with
   *   an email and password and revoke this account's tokens
   */
  constructor(storage, tokenKey, base, account) {
    this.storage = storage;
    this.tokenKey = tokenKey;
    this.base = base;
    this.account = account;
    /** @type {string|null} */
    this.token = storage.getItem(tokenKey);
  }

  /** @param {string|null} token */
  setToken(token) {
    this.token = token;
    if (token) this.storage.setItem(this.tokenKey, token);
    else this.storage.removeItem(this.tokenKey);
  }

  /** @param {string} email @param {string} password */
  async login(email, password) {
    const data = await this.request("POST", this.account.login, { email, password });
    this.setToken(data.access_token);
    return data;
  }

  /** Revokes every token of this account on the server, then forgets it here; never fails (a
   * token the server cannot be told about expires there on its own). */
  async logout() {
    try {
      if (this.token) await this.request("POST", this.account.logout);
    } catch {
      // Forgotten here all the same.
    } finally {
      this.setToken(null);
    }
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
    const resp = await fetch(`${this.base}${path}`, requestInit(method, this.token, body, accept));
    if (resp.status === 401 && this.token) this.setToken(null);
    if (!resp.ok) throw new ApiError(resp.status, await jsonOrNull(resp));
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
