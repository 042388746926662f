/**
 * The admins' review page: sign in, pick a sequence, read its QC reports (waiting work first),
 * open one to see its per-point and per-frame errors and approve or reject it; worker quality,
 * the job table with retries, costs, the crowd's units and the team's accounts, and the overlays
 * of finished solve runs.
 */

import { ApiError } from "../common/api.js";
import { $ } from "../common/dom.js";
import { errorText, noticeLine, showNotice } from "../common/notice.js";
import { startSession } from "../common/session.js";
import { AdminApi } from "./api.js";
import { ConfirmBox } from "./confirm.js";
import { initCrowd, showCrowd } from "./crowd.js";
import { orderReports, pageOf, parseRoute, pointNames, tallyReports } from "./core/format.js";
import { rejectQuestion } from "./core/queue-core.js";
import { renderFrameCosts } from "./frame-costs.js";
import { initRig, showRigHealth } from "./rig.js";
import { initSolve, showSolveRuns } from "./solve.js";
import { initProject, sequencesProgress, showJobRows, showProgress } from "./project.js";
import { ReviewQueue } from "./queue.js";
import { showReviewIn } from "./review.js";
import {
  barChart, renderCosts, renderFacts, renderReports, renderSequences,
  renderSwaps, renderWorkers,
} from "./views.js";
import { initTeam, showTeam } from "./team.js";
import { crowdWorkers, initWorkers, openWorker } from "./workers.js";

const api = new AdminApi(window.sessionStorage);
const VIEWS = ["login-view", "sequences-view", "sequence-view", "workers-view", "jobs-view",
  "costs-view", "queue-view", "crowd-view", "team-view"];

const notice = noticeLine($("notice"), () => show("login-view"));
const { notify, fail } = notice;
const queue = new ReviewQueue(api, fail);
/** Asks before a report's Reject. */
const rejectBox = new ConfirmBox($("decision-confirm"), fail);

/** What the sequence view shows, kept so the outcome filter re-renders without a request. */
const state = {
  /** @type {number|null} */ sequence: null,
  /** @type {any[]} */ reports: [],
  /** @type {number|null} */ assignment: null,
  /** @type {any[]} */ runs: [],
  /** @type {string[]} */ serials: [],
};

/** @param {string} id */
function show(id) {
  for (const view of VIEWS) $(view).hidden = view !== id;
  $("nav").hidden = id === "login-view";
}

const body = (/** @type {string} */ id) => /** @type {HTMLTableSectionElement} */ ($(id));

/** Rows a page of the sequence and worker listings holds. */
const SEQUENCE_PAGE = 50;
const WORKER_PAGE = 200;

/**
 * Fill a listing's pager: which rows are shown, and links to the pages around them.
 * @param {string} id  the pager's element
 * @param {string} route  the listing's hash, e.g. "#/sequences"
 * @param {string} noun  what the rows are
 * @param {ReturnType<typeof pageOf>} page
 */
function renderPager(id, route, noun, page) {
  const pager = $(id);
  pager.hidden = page.previous === null && page.next === null;
  const link = (/** @type {string} */ text, /** @type {number|null} */ offset) => {
    const a = document.createElement("a");
    a.textContent = text;
    if (offset === null) a.setAttribute("aria-disabled", "true");
    else a.href = offset ? `${route}/from/${offset}` : route;
    return a;
  };
  const where = document.createElement("span");
  where.textContent = page.first ? `${noun} ${page.first}–${page.last}` : `no more ${noun}`;
  pager.replaceChildren(link("‹ Previous", page.previous), where, link("Next ›", page.next));
}

/** @param {number} offset */
async function showSequences(offset) {
  const [rows, progress] = await Promise.all([api.sequences(offset, SEQUENCE_PAGE + 1),
    sequencesProgress(offset, SEQUENCE_PAGE)]);
  const sequences = rows.slice(0, SEQUENCE_PAGE);
  renderSequences(body("sequence-rows"), sequences, progress);
  renderPager("sequence-pager", "#/sequences", "sequences",
    pageOf(offset, SEQUENCE_PAGE, sequences.length, rows.length > SEQUENCE_PAGE));
  $("no-sequences").hidden = sequences.length > 0 || offset > 0;
  show("sequences-view");
}

/** @param {number} sequenceId @param {number|null} assignmentId */
async function showSequence(sequenceId, assignmentId) {
  const [sequence, reports, runs] = await Promise.all([api.sequence(sequenceId),
    api.reports(sequenceId), api.solveRuns(sequenceId)]);
  $("sequence-title").textContent = `${sequence.subject}/${sequence.name} (#${sequence.id})`;
  const serials = sequence.cameras.map((/** @type {any} */ c) => c.serial);
  Object.assign(state, { sequence: sequenceId, reports, assignment: assignmentId, runs, serials });
  renderReportList();
  showSolveRuns(sequenceId, runs, serials);
  await showRigHealth(sequenceId);
  $("report-detail").hidden = true;
  $("report-review").hidden = true;
  await showProgress(sequenceId);
  show("sequence-view");
  if (assignmentId !== null) await showReport(assignmentId);
}

function renderReportList() {
  const outcome = /** @type {HTMLSelectElement} */ ($("outcome-filter")).value;
  const shown = orderReports(state.reports, outcome);
  renderReports(body("report-rows"), shown, Number(state.sequence), state.assignment);
  const t = tallyReports(state.reports);
  $("report-tally").textContent = `${state.reports.length} reports: ${t.approve} approve, `
    + `${t.review} review, ${t.reject} reject; ${t.waiting} waiting for an admin`;
  $("no-reports").hidden = shown.length > 0;
}

/** @param {number} assignmentId */
async function showReport(assignmentId) {
  const report = await api.report(assignmentId);
  $("detail-title").textContent = `Assignment ${report.assignment_id}`;
  $("detail-close").setAttribute("href", `#/sequences/${report.sequence_id}`);
  renderFacts($("detail-facts"), report);
  const names = pointNames(report.target_key, report.per_joint.length);
  $("joint-chart").replaceChildren(barChart(report.per_joint, names, "per-joint", true));
  const frames = report.per_frame.map((/** @type {unknown} */ _, /** @type {number} */ i) =>
    `frame ${i}`);
  $("frame-chart").replaceChildren(barChart(report.per_frame, frames, "per-frame"));
  renderSwaps($("detail-swaps"), report.swaps);
  const feedback = /** @type {HTMLTextAreaElement} */ ($("decision-feedback"));
  feedback.value = report.feedback || "";
  $("approve").dataset.assignment = String(report.assignment_id);
  $("decision-result").hidden = true;
  $("report-detail").hidden = false;
  await showReviewIn($("report-review"), api, report.assignment_id);
}

/** @param {"approve"|"reject"} kind  @param {boolean} [confirmed]  a rejection was confirmed */
async function decide(kind, confirmed = false) {
  const assignmentId = Number($("approve").dataset.assignment);
  const feedback = /** @type {HTMLTextAreaElement} */ ($("decision-feedback")).value.trim();
  const say = (/** @type {string} */ text, /** @type {"info"|"error"} */ kind) =>
    showNotice($("decision-result"), text, kind);
  if (kind === "reject" && !feedback) {
    say("A rejection needs feedback: tell the worker what was wrong.", "error");
    return;
  }
  if (kind === "reject" && !confirmed) {
    // Final for the worker (their approval rate, their pay): asked first, nothing sent before.
    say("", "info");
    rejectBox.ask(rejectQuestion(assignmentId), () => decide("reject", true),
      { detail: feedback, yes: "Reject", danger: true });
    return;
  }
  const buttons = [$("approve"), $("reject")].map((b) => /** @type {HTMLButtonElement} */ (b));
  // One decision at a time: a second click while the first is on its way would only be refused.
  for (const button of buttons) button.disabled = true;
  try {
    const payment = kind === "approve" ? await api.approve(assignmentId, feedback)
      : await api.reject(assignmentId, feedback);
    const verb = kind === "approve" ? "Approved" : "Rejected";
    state.reports = await api.reports(Number(state.sequence));
    renderReportList();
    say(`${verb} assignment ${assignmentId}${payment.already_done ? " (already done)" : ""}.`,
      "info");
  } catch (err) {
    if (err instanceof ApiError && err.status === 401) fail(err);
    else say(errorText(err), "error");
  } finally {
    for (const button of buttons) button.disabled = false;
  }
}

/** @param {number} offset */
async function showWorkers(offset) {
  const rows = await crowdWorkers(offset, WORKER_PAGE + 1);
  const workers = rows.slice(0, WORKER_PAGE);
  renderWorkers(body("worker-rows"), workers, openWorker());
  renderPager("worker-pager", "#/workers", "workers",
    pageOf(offset, WORKER_PAGE, workers.length, rows.length > WORKER_PAGE));
  $("no-workers").hidden = workers.length > 0 || offset > 0;
  show("workers-view");
}

async function showJobs() {
  await showJobRows();
  show("jobs-view");
}

/** @param {number} jobId */
async function retry(jobId) {
  try {
    const job = await api.retryJob(jobId);
    notify(`Job ${job.id} (${job.key}) is ${job.status} again.`);
    await showJobs();
  } catch (err) {
    fail(err);
  }
}

async function showCosts() {
  const [costs, frameCosts] = await Promise.all([api.costs(), api.frameCosts()]);
  renderFrameCosts($("frame-costs"), frameCosts);
  renderCosts({
    summary: $("cost-summary"), sequenceHead: $("cost-head-sequence"),
    sequences: $("cost-sequence-rows"), workerHead: $("cost-head-worker"),
    workers: $("cost-worker-rows"),
  }, costs);
  show("costs-view");
}

async function route() {
  if (!api.token) {
    show("login-view");
    return;
  }
  const where = parseRoute(location.hash);
  queue.leave();
  try {
    if (/^#\/queue(\/|$)/.test(location.hash)) {
      show("queue-view");
      await queue.show(Number(location.hash.split("/")[2]) || null);
    } else if (where.view === "workers") await showWorkers(where.offset);
    else if (where.view === "jobs") await showJobs();
    else if (where.view === "costs") await showCosts();
    else if (where.view === "crowd") {
      await showCrowd(where.sequence);
      show("crowd-view");
    }
    else if (where.view === "team") await showTeam().then(() => show("team-view"));
    else if (where.sequence !== null) await showSequence(where.sequence, where.assignment);
    else await showSequences(where.offset);
  } catch (err) {
    fail(err);
  }
}

async function loadMe() {
  const me = await api.me();
  $("who").textContent = me.email;
}

/** How often a running export is looked at, milliseconds. */
const EXPORT_POLL_MS = 1000;

/**
 * Export one sequence (or the project, null) in the chosen format: start the job, show its
 * progress, then save the archive.
 * @param {number|null} sequenceId
 */
async function exportLabels(sequenceId) {
  const format = /** @type {HTMLSelectElement} */ ($("export-format")).value;
  const status = $("export-status");
  const what = sequenceId === null ? "project" : `sequence #${sequenceId}`;
  status.title = "";
  let job = await api.startExport(format, sequenceId === null ? null : [sequenceId]);
  while (job.status !== "done" && job.status !== "failed") {
    const p = job.progress || {};
    status.textContent = `${format} export of ${what}: ${job.status}` +
      (p.total ? ` (${p.done} of ${p.total} views)` : "");
    await new Promise((resolve) => setTimeout(resolve, EXPORT_POLL_MS));
    job = await api.exportState(job.id);
  }
  if (job.status === "failed") {
    status.textContent = "";
    throw new Error(`${format} export of ${what} failed: ${job.error || "see the job table"}`);
  }
  const blob = await api.exportArchive(job.id);
  const link = document.createElement("a");
  link.href = URL.createObjectURL(blob);
  link.download = `dexlabel-${format}-${sequenceId === null ? "project" : sequenceId}.${job.archive}`;
  link.click();
  setTimeout(() => URL.revokeObjectURL(link.href), 60_000);
  const size = blob.size < 1e6 ? `${Math.max(1, Math.round(blob.size / 1e3))} kB`
    : `${(blob.size / 1e6).toFixed(1)} MB`;
  const skipped = /** @type {string[]} */ (job.skipped || []);
  status.textContent = `${format} export of ${what}: done, saved ${link.download} (${size})` +
    (skipped.length ? `; ${job.sequence_ids.length} exported, ${skipped.length} left out ` +
      `(${skipped[0]}${skipped.length > 1 ? "; …" : ""})` : "");
  status.title = skipped.join("\n");
}

function start() {
  queue.bind();
  $("outcome-filter").addEventListener("change", renderReportList);
  $("approve").addEventListener("click", () => decide("approve"));
  $("reject").addEventListener("click", () => decide("reject"));
  $("job-rows").addEventListener("click", (e) => {
    const button = /** @type {HTMLElement} */ (e.target).closest("button[data-retry]");
    if (button) retry(Number(/** @type {HTMLElement} */ (button).dataset.retry));
  });
  $("export-project").addEventListener("click", () => exportLabels(null).catch(fail));
  $("sequence-rows").addEventListener("click", (e) => {
    const button = /** @type {HTMLElement} */ (e.target).closest("button[data-export]");
    if (button) exportLabels(Number(/** @type {HTMLElement} */ (button).dataset.export)).catch(fail);
  });
  initSolve(api, fail);
  initRig(api, fail);
  initProject(api, fail, route);
  initWorkers(api, fail);
  initCrowd(api, fail);
  initTeam(api, fail);
  startSession({ api, notice, signedOut: () => show("login-view"), loadMe, route });
}

start();
