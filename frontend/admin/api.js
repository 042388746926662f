/**
 * The admin REST API (/api). The admin's signed token travels as a bearer header and is kept in
 * sessionStorage, never in a cookie.
 */

const TOKEN_KEY = "dexlabel.admin.token";

export class ApiError extends Error {
  /** @param {number} status @param {any} data */
  constructor(status, data) {
    const detail = data && data.detail;
    super(typeof detail === "string" ? detail : `request failed (${status})`);
    this.status = status;
  }
}

export class AdminApi {
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
   * @param {string} path   below /api
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
    const resp = await fetch(`/api${path}`, init);
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
   * A JSON request; the reply's body, or an ApiError with the API's detail.
   * @param {string} method @param {string} path @param {object} [body]
   */
  async request(method, path, body) {
    const resp = await this.send(method, path, body);
    return resp.json();
  }

  /** @param {string} email @param {string} password */
  async login(email, password) {
    const data = await this.request("POST", "/auth/token", { email, password });
    this.setToken(data.access_token);
    return data;
  }

  me() { return this.request("GET", "/auth/me"); }
  sequences() { return this.request("GET", "/sequences"); }
  /** @param {number} id */
  sequence(id) { return this.request("GET", `/sequences/${id}`); }
  /** @param {number} sequenceId */
  reports(sequenceId) { return this.request("GET", `/qc/reports?sequence_id=${sequenceId}`); }
  /** @param {number} assignmentId */
  report(assignmentId) { return this.request("GET", `/qc/reports/${assignmentId}`); }
  workers() { return this.request("GET", "/qc/workers"); }
  jobs() { return this.request("GET", "/jobs"); }
  /** @param {number} jobId */
  retryJob(jobId) { return this.request("POST", `/jobs/${jobId}/retry`); }
  costs() { return this.request("GET", "/crowd/costs"); }
  /** @param {number} sequenceId */
  solveRuns(sequenceId) { return this.request("GET", `/sequences/${sequenceId}/solve-runs`); }

  /**
   * @param {number} assignmentId
   * @param {string} feedback  sent when not empty
   */
  approve(assignmentId, feedback) {
    return this.request("POST", `/crowd/assignments/${assignmentId}/approve`,
      feedback ? { feedback } : {});
  }

  /** @param {number} assignmentId @param {string} feedback  required by the API */
  reject(assignmentId, feedback) {
    return this.request("POST", `/crowd/assignments/${assignmentId}/reject`, { feedback });
  }

  /**
   * A solve run's overlay of one frame and view, as a Blob (the bearer header rules out a
   * plain <img src>).
   * @param {number} runId @param {number} frame @param {string} view  serial or index
   */
  async overlay(runId, frame, view) {
    const path = `/solve-runs/${runId}/frames/${frame}/views/${encodeURIComponent(view)}.png`;
    const resp = await this.send("GET", path, undefined, "image/png");
    return resp.blob();
  }
}
