/**
 * The admin REST API (/api). The admin's signed token travels as a bearer header and is kept in
 * sessionStorage, never in a cookie.
 */

import { BearerClient } from "../common/api.js";

export class AdminApi extends BearerClient {
  /** @param {Storage} storage */
  constructor(storage) {
    super(storage, "dexlabel.admin.token", "/api",
      { login: "/auth/token", logout: "/auth/logout" });
  }

  me() { return this.request("GET", "/auth/me"); }
  /** A page of sequences. @param {number} offset @param {number} limit */
  sequences(offset, limit) {
    return this.request("GET", `/sequences?offset=${offset}&limit=${limit}`);
  }
  /** @param {number} id */
  sequence(id) { return this.request("GET", `/sequences/${id}`); }
  /** @param {number} sequenceId */
  reports(sequenceId) { return this.request("GET", `/qc/reports?sequence_id=${sequenceId}`); }
  /** @param {number} assignmentId */
  report(assignmentId) { return this.request("GET", `/qc/reports/${assignmentId}`); }
  /** A page of workers. @param {number} offset @param {number} limit */
  workers(offset, limit) {
    return this.request("GET", `/qc/workers?offset=${offset}&limit=${limit}`);
  }
  jobs() { return this.request("GET", "/jobs"); }
  /** @param {number} jobId */
  retryJob(jobId) { return this.request("POST", `/jobs/${jobId}/retry`); }
  costs() { return this.request("GET", "/crowd/costs"); }
  /** Cost per labelled 3D frame, per sequence and target (the first 200 sequences). */
  frameCosts() { return this.request("GET", "/frame-costs?limit=200"); }
  /** @param {number} sequenceId */
  solveRuns(sequenceId) { return this.request("GET", `/sequences/${sequenceId}/solve-runs`); }
  /** @param {number} sequenceId */
  rigHealth(sequenceId) { return this.request("GET", `/sequences/${sequenceId}/rig-health`); }
  /** Queue a new rig-health estimate. @param {number} sequenceId */
  estimateRig(sequenceId) {
    return this.request("POST", `/sequences/${sequenceId}/rig-health`);
  }
  /** Put a calibration version in use (0: imported) and re-solve.
   * @param {number} sequenceId @param {number} version */
  adoptCalibration(sequenceId, version) {
    return this.request("POST", `/sequences/${sequenceId}/calibrations/${version}/adopt`,
      { solve: true });
  }

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
   * Start an export job (POST /api/exports).
   * @param {string} format  dexycb, coco, bop, cvat or json
   * @param {number[]|null} sequences  null: the whole project
   */
  startExport(format, sequences) {
    return this.request("POST", "/exports", sequences ? { format, sequences } : { format, all: true });
  }

  /** @param {number} exportId */
  exportState(exportId) { return this.request("GET", `/exports/${exportId}`); }

  /** A finished export's archive as a Blob. @param {number} exportId */
  async exportArchive(exportId) {
    const resp = await this.send("GET", `/exports/${exportId}/download`, undefined, "*/*");
    return resp.blob();
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
