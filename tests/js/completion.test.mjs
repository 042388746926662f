// How a submitted page completes: the step chosen from the start reply's completion, the
// page's address and whether the page is framed.
import assert from "node:assert/strict";
import { test } from "node:test";

import { readPageParams, sendCompletionForm } from "../../frontend/annotate/api.js";
import {
  checkedCompletion,
  completionEntries,
  completionFromFragment,
  completionStep,
} from "../../frontend/annotate/core/completion.js";

const PAGE = "https://labels.example.org/annotate/?assignmentId=A1";
const PROLIFIC = "https://app.prolific.com/submissions/complete?cc=C1A2B3C4";
const ALONE = { framed: false, base: PAGE };
const FRAMED = { framed: true, base: PAGE };

/** The page's parameters with a completion. */
function params(completion, extra = {}) {
  return { completion, turkSubmitTo: "https://market.example/", assignmentId: "A1",
    preview: false, ...extra };
}

test("no completion: the externalSubmit form as before, or nothing without turkSubmitTo", () => {
  assert.deepEqual(completionStep(params(null), FRAMED),
    { action: "form", url: "https://market.example/mturk/externalSubmit", assignmentId: "A1" });
  assert.deepEqual(completionStep(params(null, { turkSubmitTo: null }), ALONE),
    { action: "none" });
  assert.deepEqual(completionStep(params(null, { preview: true }), FRAMED), { action: "none" });
});

test("form_post posts to turkSubmitTo, or to its own url when it names one", () => {
  const mturk = { kind: "form_post", url: "" };
  assert.deepEqual(completionStep(params(mturk), FRAMED),
    { action: "form", url: "https://market.example/mturk/externalSubmit", assignmentId: "A1" });
  const own = { kind: "form_post", url: "https://crowd.example/done" };
  assert.equal(completionStep(params(own), FRAMED).url, "https://crowd.example/done");
  assert.deepEqual(completionStep(params(mturk, { assignmentId: null }), FRAMED),
    { action: "none" });
});

test("redirect sends the whole window when framed, the page itself when alone", () => {
  const prolific = { kind: "redirect", url: PROLIFIC };
  assert.deepEqual(completionStep(params(prolific), FRAMED), { action: "top", url: PROLIFIC });
  assert.deepEqual(completionStep(params(prolific), ALONE),
    { action: "navigate", url: PROLIFIC });
  assert.deepEqual(completionStep(params(prolific, { preview: true }), ALONE),
    { action: "none" });
});

test("portal tells the framing portal, to its origin only; alone it opens the list", () => {
  const team = { kind: "portal", url: "/market/#/hits" };
  const handIn = { url: "https://market.example/mturk/externalSubmit", assignmentId: "A1" };
  assert.deepEqual(completionStep(params(team), FRAMED), {
    action: "parent", url: "https://labels.example.org/market/#/hits",
    origin: "https://labels.example.org", handIn });
  const elsewhere = { kind: "portal", url: "https://portal.example.org:8443/market/" };
  assert.equal(completionStep(params(elsewhere), FRAMED).origin,
    "https://portal.example.org:8443");
  assert.deepEqual(completionStep(params(team), ALONE),
    { action: "navigate", url: "https://labels.example.org/market/#/hits", handIn });
  assert.deepEqual(completionStep(params(team, { turkSubmitTo: null }), ALONE),
    { action: "navigate", url: "https://labels.example.org/market/#/hits" });
});

test("a portal completion hands the assignment to the marketplace's form first", async () => {
  const sent = [];
  const fetchFn = async (url, init) => {
    sent.push([url, init.method, String(init.body)]);
    return { ok: url.endsWith("/externalSubmit") };
  };
  assert.equal(await sendCompletionForm(fetchFn, "https://m.example/mturk/externalSubmit",
    "A1", "submitted:7"), true);
  assert.deepEqual(sent, [["https://m.example/mturk/externalSubmit", "POST",
    "assignmentId=A1&result=submitted%3A7"]]);
  assert.equal(await sendCompletionForm(fetchFn, "https://m.example/other", "A1", "x"), false);
  const down = async () => { throw new TypeError("network"); };
  assert.equal(await sendCompletionForm(down, "https://m.example/x", "A1", "x"), false);
});

test("a completion the page cannot follow is dropped: unknown kind, no web address", () => {
  assert.equal(checkedCompletion({ kind: "redirect", url: "javascript:alert(1)" }), null);
  assert.equal(checkedCompletion({ kind: "redirect", url: "" }), null);
  assert.equal(checkedCompletion({ kind: "portal" }), null);
  assert.equal(checkedCompletion({ kind: "email", url: PROLIFIC }), null);
  assert.equal(checkedCompletion({ kind: "form_post", url: "data:text/html,x" }), null);
  assert.equal(checkedCompletion(null), null);
  assert.deepEqual(checkedCompletion({ kind: "form_post", url: null }),
    { kind: "form_post", url: "" });
  assert.deepEqual(checkedCompletion({ kind: "redirect", url: PROLIFIC, extra: 1 }),
    { kind: "redirect", url: PROLIFIC });
});

test("the completion survives a reload in the fragment beside the token", () => {
  const prolific = { kind: "redirect", url: PROLIFIC };
  const hash = `#${new URLSearchParams([["token", "A.sig"], ...completionEntries(prolific)])}`;
  const read = readPageParams("?assignmentId=A1", hash);
  assert.equal(read.token, "A.sig");
  assert.deepEqual(read.completion, prolific);
  assert.deepEqual(completionEntries({ kind: "form_post", url: "" }),
    [["completion", "form_post"]]);
  assert.deepEqual(completionEntries(null), []);
  assert.equal(readPageParams("?assignmentId=A1", "#token=A.sig").completion, null);
  const forged = new URLSearchParams("completion=redirect&completion_url=javascript:alert(1)");
  assert.equal(completionFromFragment(forged), null);
});
