/**
 * Project control on the admin page: import a capture, each sequence's progress (a summary
 * per listed sequence, the view x target grid on its page), create its tasks, publish them
 * to the provider chosen (the team: to a member or to all) with the count and the cost in its
 * fees shown first; the job table's filters and whole results. Each
 * worker's record is workers.js's.
 */

import { $, el } from "../common/dom.js";
import { showFailure, showNotice } from "../common/notice.js";
import { PROVIDERS } from "./core/crowd-format.js";
import { JOB_STATUSES, costLine, inCurrency, jobQuery } from "./core/project-format.js";
import { progressSummary, renderJobs, renderProgressGrid } from "./views.js";

/** @typedef {import("./api.js").AdminApi} AdminApi */

const input = (/** @type {string} */ id) => /** @type {HTMLInputElement} */ ($(id));

const state = {
  /** @type {AdminApi|null} */ api: null,
  /** @type {(err: unknown) => void} */ fail: () => {},
  /** The sequence whose page is shown. @type {number|null} */ sequence: null,
  /** The publish options the shown cost is for (JSON), and its HIT count. */
  /** @type {string|null} */ planned: null,
  plannedHits: 0,
  /** Jobs shown whole. @type {Set<number>} */ expanded: new Set(),
  /** The listing shown again after an import. @type {() => unknown} */ refresh: () => {},
};

function api() {
  if (!state.api) throw new Error("initProject was not called");
  return state.api;
}

/**
 * A message in a status line of the page: a reply's detail for an API error.
 * @param {string} id  @param {string} text  @param {"info"|"error"} [kind]
 */
function say(id, text, kind = "info") {
  showNotice($(id), text, kind);
}

/**
 * Show an error where the action was asked for (a 401 goes to the page, which signs out).
 * @param {string} id  @param {string} what  the action, e.g. "Publish"  @param {unknown} err
 */
function failed(id, what, err) {
  showFailure($(id), what, err, state.fail);
}

// ----- sequences ---------------------------------------------------------------------------

/**
 * The progress of a page of sequences (GET /api/progress: the page GET /api/sequences gives
 * for the same offset and limit), by sequence id.
 * @param {number} offset  @param {number} limit
 * @returns {Promise<Map<number, any>>}
 */
export async function sequencesProgress(offset, limit) {
  const page = await api().request("GET", `/progress?offset=${offset}&limit=${limit}`);
  return new Map(page.map((/** @type {any} */ p) => [p.sequence_id, p]));
}

/** @param {SubmitEvent} event */
async function importCapture(event) {
  event.preventDefault();
  const path = input("import-path").value.trim();
  const button = /** @type {HTMLButtonElement} */ ($("import-start"));
  button.disabled = true;
  say("import-status", `Importing ${path} …`);
  try {
    const results = await api().request("POST", "/captures/import", { path });
    const lines = results.map((/** @type {any} */ r) => `${r.subject}/${r.name} (#${r.sequence_id}`
      + `, ${r.num_cameras} views, ${r.num_frames} frames): ${r.created ? "imported"
        : "already imported"}${r.repaired ? `, ${r.repaired} files written again` : ""}`);
    say("import-status", lines.length ? lines.join("; ") : `No sequence found in ${path}.`,
      lines.length ? "info" : "error");
    await state.refresh();
  } catch (err) {
    failed("import-status", `Import of ${path}`, err);
  } finally {
    button.disabled = false;
  }
}

/**
 * The progress grid of a sequence's page, and its controls set for that sequence.
 * @param {number} sequenceId
 */
export async function showProgress(sequenceId) {
  if (state.sequence !== sequenceId) {
    state.sequence = sequenceId;
    forgetPlan();
    say("project-status", "");
  }
  const [p] = await Promise.all([api().request("GET", `/sequences/${sequenceId}/progress`),
    fillProviders()]);
  renderProgressGrid(/** @type {HTMLTableElement} */ ($("progress-grid")), p);
  $("progress-grid").hidden = p.tasks.length === 0;
  $("no-tasks").hidden = p.tasks.length > 0;
  $("progress-summary").replaceChildren(progressSummary(p));
  $("sequence-units").setAttribute("href", `#/crowd/${sequenceId}`);
  return p;
}

async function createTasks() {
  const id = Number(state.sequence);
  try {
    const before = (await showProgress(id)).tasks.length;
    const tasks = await api().request("POST", `/sequences/${id}/tasks`);
    const made = tasks.length - before;
    say("project-status", made > 0 ? `Created ${made} tasks (${tasks.length} in all).`
      : `Every task already exists (${tasks.length}); nothing created.`);
    forgetPlan();
    await showProgress(id);
  } catch (err) {
    failed("project-status", "Creating tasks", err);
  }
}

/** The publish options of the form, as the API takes them: the provider chosen, and for the
 * team the member it is assigned to (none: open to the whole team) and no approval rate (a
 * new member has no record to meet it with). */
function publishOptions() {
  const provider = input("publish-provider").value;
  const team = provider === "team";
  const approval = team ? "" : input("publish-approval").value.trim();
  const assignee = team ? input("publish-assignee").value.trim() : "";
  const policy = /** @type {HTMLSelectElement} */ ($("publish-policy")).value;
  return {
    sequence_id: state.sequence, provider, reward: input("publish-reward").value.trim(),
    max_assignments: Number(input("publish-assignments").value),
    min_approval_rate: approval === "" ? null : Number(approval),
    ...(assignee ? { assignee } : {}),
    ...(policy ? { policy } : {}),
  };
}

/** The providers to choose from, the setting's default chosen (asked once). */
async function fillProviders() {
  const select = /** @type {HTMLSelectElement} */ ($("publish-provider"));
  if (select.options.length) return;
  const offered = await api().request("GET", "/crowd/providers");
  select.replaceChildren(...PROVIDERS.filter(([key]) => offered.choices.includes(key))
    .map(([key, name]) => el("option", { value: key }, [name])));
  select.value = offered.default;
}

/** The assignee field shows for the team only, its choices the team's accounts; the
 * approval rate for the others only. */
async function providerChanged() {
  forgetPlan();
  const team = input("publish-provider").value === "team";
  $("publish-assignee-field").hidden = !team;
  $("publish-approval-field").hidden = team;
  if (!team || $("publish-team").childElementCount) return;
  const members = await api().request("GET", "/crowd/team");
  $("publish-team").replaceChildren(...members.map((/** @type {any} */ m) =>
    el("option", { value: m.worker_id }, [m.email])));
}

function forgetPlan() {
  state.planned = null;
  state.plannedHits = 0;
  const button = /** @type {HTMLButtonElement} */ ($("publish-confirm"));
  button.disabled = true;
  button.textContent = "Publish";
  $("publish-cost").textContent = "";
}

/** Ask the API what a publish would cost (a dry run); only then can it be confirmed. */
async function checkCost() {
  forgetPlan();
  const options = publishOptions();
  try {
    const plan = await api().request("POST", "/crowd/publish", { ...options, dry_run: true });
    const provider = /** @type {HTMLSelectElement} */ ($("publish-provider"));
    // The team's pay is the lab's own record: nothing reaches anyone's account.
    const recorded = provider.value === "team" ? " (recorded only: the team is paid nothing "
      + "through dexlabel)" : "";
    $("publish-cost").textContent = plan.cost.hits
      ? `${provider.selectedOptions[0]?.textContent}: ${costLine(plan)}${recorded}`
      : costLine(plan);
    $("publish-cost").dataset.provider = provider.value;
    $("publish-cost").dataset.hits = String(plan.cost.hits);
    $("publish-cost").dataset.total = plan.cost.total;
    say("project-status", "");
    if (plan.cost.hits > 0) {
      state.planned = JSON.stringify(options);
      state.plannedHits = plan.cost.hits;
      const button = /** @type {HTMLButtonElement} */ ($("publish-confirm"));
      button.disabled = false;
      button.textContent = `Publish ${plan.cost.hits} HITs for `
        + inCurrency(plan.cost.total, plan.cost.currency);
    }
  } catch (err) {
    failed("project-status", "Checking the cost", err);
  }
}

async function publish() {
  const options = publishOptions();
  if (state.planned !== JSON.stringify(options)) {
    forgetPlan();
    say("project-status", "The settings changed: check the cost again first.", "error");
    return;
  }
  const button = /** @type {HTMLButtonElement} */ ($("publish-confirm"));
  button.disabled = true;
  try {
    const done = await api().request("POST", "/crowd/publish", options);
    forgetPlan();
    const extra = [done.recovered ? `${done.recovered} recovered` : "",
      done.already_published ? `${done.already_published} already published` : ""]
      .filter(Boolean).join(", ");
    say("project-status", `Published ${done.created} HITs${extra ? ` (${extra})` : ""} `
      + `for ${inCurrency(done.cost.total, done.cost.currency)}.`);
    $("project-status").dataset.created = String(done.created);
    await showProgress(Number(state.sequence));
  } catch (err) {
    button.disabled = false;
    failed("project-status", "Publishing", err);
  }
}

// ----- jobs --------------------------------------------------------------------------------

/** The job table under the chosen filters, its kinds listed with their counts. */
export async function showJobRows() {
  const status = /** @type {HTMLSelectElement} */ ($("job-status")).value;
  const kindSelect = /** @type {HTMLSelectElement} */ ($("job-kind"));
  const [jobs, counts] = await Promise.all([
    api().request("GET", `/jobs${jobQuery(status, kindSelect.value)}`),
    api().request("GET", "/jobs/counts")]);
  const kind = kindSelect.value;
  const total = (/** @type {Record<string, number>} */ c) =>
    Object.values(c).reduce((a, b) => a + b, 0);
  kindSelect.replaceChildren(el("option", { value: "" }, ["all"]),
    ...Object.entries(counts.kinds).map(([k, c]) => el("option", { value: k },
      [`${k} (${total(/** @type {Record<string, number>} */ (c))})`])));
  kindSelect.value = kind in counts.kinds ? kind : "";
  renderJobs(/** @type {HTMLTableSectionElement} */ ($("job-rows")), jobs, state.expanded);
  $("no-jobs").hidden = jobs.length > 0;
  $("no-jobs").textContent = status || kind ? "No jobs match these filters." : "No jobs.";
  return jobs;
}

/** @param {number} jobId */
function toggleJob(jobId) {
  if (state.expanded.has(jobId)) state.expanded.delete(jobId);
  else state.expanded.add(jobId);
  showJobRows().catch(state.fail);
}

// ----- wiring ------------------------------------------------------------------------------

/**
 * @param {AdminApi} client
 * @param {(err: unknown) => void} fail  the page's handler of errors (a 401 signs out)
 * @param {() => unknown} refresh  shows the current route again
 */
export function initProject(client, fail, refresh) {
  Object.assign(state, { api: client, fail, refresh });
  $("import-form").addEventListener("submit",
    (e) => importCapture(/** @type {SubmitEvent} */ (e)));
  $("create-tasks").addEventListener("click", createTasks);
  $("publish-check").addEventListener("click", checkCost);
  $("publish-confirm").addEventListener("click", publish);
  for (const id of ["publish-reward", "publish-assignments", "publish-approval",
    "publish-assignee"]) {
    $(id).addEventListener("input", forgetPlan);
  }
  $("publish-provider").addEventListener("change", () => providerChanged().catch(fail));
  $("job-status").replaceChildren(el("option", { value: "" }, ["all"]),
    ...JOB_STATUSES.map((s) => el("option", { value: s }, [s])));
  for (const id of ["job-status", "job-kind"]) {
    $(id).addEventListener("change", () => showJobRows().catch(fail));
  }
  $("job-rows").addEventListener("click", (e) => {
    const button = /** @type {HTMLElement} */ (e.target).closest("button[data-expand]");
    if (button) toggleJob(Number(/** @type {HTMLElement} */ (button).dataset.expand));
  });
}
