// Assisted annotation: spans, proposal and pre-fill writes, re-tracks after a correction,
// epipolar lines.
import assert from "node:assert/strict";
import { test } from "node:test";

import { Assist } from "../../frontend/annotate/core/assist.js";
import { clipLine, epipolarLines } from "../../frontend/annotate/core/epipolar.js";
import {
  acceptViewed, allSpans, anchorRows, countTracked, handKeyedBefore, heldFrames, modelProposals,
  modelText, openSpanAround, openSpans, prefillEntries, proposalEntries, proposalRequest, retrackSpans, spanAround, stopText,
  trackedText,
} from "../../frontend/annotate/core/proposals.js";
import { AnnotationStore } from "../../frontend/annotate/core/store.js";
import { ViewedFrames } from "../../frontend/annotate/core/viewed.js";

const kf = (frame, x, y, source = "placed", visible = true) => ({ frame, x, y, visible, source });

test("spanAround: between the hand-set keyframes around the frame, tracked ones skipped", () => {
  const keyframes = [kf(0, 10, 10), kf(4, 14, 10, "tracked"), kf(9, 19, 10), kf(20, 30, 10)];
  assert.deepEqual(spanAround(keyframes, 4), [[0, 9]]);
  assert.deepEqual(spanAround(keyframes, 0), [[0, 9]]);
  assert.deepEqual(spanAround(keyframes, 9), [[9, 20]]);
  assert.deepEqual(spanAround(keyframes, 20), [[9, 20]]);
  assert.deepEqual(spanAround(keyframes, 25), []);
  assert.deepEqual(spanAround([kf(0, 1, 1), kf(1, 2, 2)], 0), [], "adjacent frames: nothing");
  const occluded = [kf(0, 1, 1), kf(6, 2, 2, "placed", false)];
  assert.deepEqual(spanAround(occluded, 3), [], "an occluded end is not tracked from");
});

test("allSpans and anchorRows leave tracked keyframes out", () => {
  const keyframes = [kf(0, 1, 2), kf(3, 4, 5, "tracked"), kf(6, 7, 8, "edited"),
    kf(7, 7, 8), kf(12, 9, 9, "prefilled")];
  assert.deepEqual(allSpans(keyframes), [[0, 6], [7, 12]]);
  assert.deepEqual(anchorRows(keyframes),
    [[0, 1, 2, 1], [6, 7, 8, 1], [7, 7, 8, 1], [12, 9, 9, 1]]);
});

test("proposalEntries: ok proposals become tracked, lost frames drop old tracked keyframes", () => {
  const keyframes = [kf(2, 0, 0), kf(4, 5, 5, "tracked"), kf(5, 6, 6, "tracked"), kf(6, 9, 9),
    kf(8, 1, 1)];
  const proposal = {
    point: 0, first: 2, last: 8, spans: [[2, 8]],
    xy: [null, [3, 3], [4, 4], [5.5, 5.5], null, [7, 7], null],
    ok: [false, true, false, true, false, true, false],
  };
  assert.deepEqual(proposalEntries(keyframes, proposal), [
    { frame: 3, x: 3, y: 3, visible: true, source: "tracked" },
    { frame: 4, remove: true },
    { frame: 5, x: 5.5, y: 5.5, visible: true, source: "tracked" },
    { frame: 7, x: 7, y: 7, visible: true, source: "tracked" },
  ]);
  const counts = countTracked([proposal]);
  assert.deepEqual(counts, { tracked: 3, total: 5 });
  assert.equal(trackedText({ tracked: 12, total: 14 }),
    "12 of 14 frames tracked; 2 left to interpolation");
});

test("retrackSpans: the sides of a correction that hold tracked keyframes", () => {
  const keyframes = [kf(0, 0, 0), kf(1, 1, 0, "tracked"), kf(2, 2, 0, "tracked"),
    kf(3, 3, 0, "edited"), kf(4, 4, 0, "tracked"), kf(6, 6, 0), kf(8, 8, 0)];
  assert.deepEqual(retrackSpans(keyframes, 3, 12), [[0, 3], [3, 6]]);
  assert.deepEqual(retrackSpans(keyframes, 6, 12), [[3, 6]]);
  assert.deepEqual(retrackSpans(keyframes, 8, 12), [], "no tracked keyframe beside it");
  assert.deepEqual(retrackSpans(keyframes, 2, 12), [], "a tracked keyframe is no correction");
  const followed = [kf(2, 0, 0), kf(3, 1, 0, "tracked"), kf(5, 3, 0, "edited"),
    kf(6, 4, 0, "tracked"), kf(7, 5, 0, "tracked")];
  assert.deepEqual(retrackSpans(followed, 5, 12), [[2, 5], [5, 12]],
    "past the last anchor: the open span after it");
});

test("prefillEntries: every suggested frame except those keyed by hand", () => {
  const keyframes = [kf(0, 1, 1), kf(1, 2, 2, "tracked"), kf(2, 3, 3, "edited")];
  const suggestion = { xy: [[5, 5], [6, 6], [7, 7], null, [9, 9]],
    visible: [true, null, true, true, false] };
  assert.deepEqual(prefillEntries(keyframes, suggestion), [
    { frame: 1, x: 6, y: 6, visible: true, source: "prefilled" },
    { frame: 4, x: 9, y: 9, visible: false, source: "prefilled" },
  ]);
});

test("epipolarLines: l = F [x, y, 1], normalised, and clipped to the image", () => {
  // A pure translation along x between the views: F = [t]x with t = (1, 0, 0) maps (x, y) to
  // the horizontal line through y.
  const F = [[0, 0, 0], [0, 0, -1], [0, 1, 0]];
  const epipolar = [{ serial: "cam-000123", F, xy: [[[30, 40], null]] },
    { serial: "cam-9", F: [[0, 0, 0], [0, 0, 0], [0, 0, 0]], xy: [[[1, 1], null]] }];
  const lines = epipolarLines(epipolar, 0, 0);
  assert.equal(lines.length, 1, "a degenerate F gives no line");
  const { a, b, c } = lines[0];
  assert.ok(Math.abs(Math.hypot(a, b) - 1) < 1e-12);
  assert.ok(Math.abs(a * 100 + b * 40 + c) < 1e-9, "passes through y = 40");
  assert.deepEqual(epipolarLines(epipolar, 0, 1), []);
  assert.deepEqual(clipLine(lines[0], 640, 480), [[0, 40], [640, 40]]);
  const diagonal = { a: Math.SQRT1_2, b: -Math.SQRT1_2, c: 0 };  // y = x
  assert.deepEqual(clipLine(diagonal, 100, 50), [[0, 0], [50, 50]]);
  assert.equal(clipLine({ a: 0, b: 1, c: -600 }, 640, 480), null, "y = 600 misses");
});

test("openSpanAround and openSpans: beyond the outermost visible anchor, inside the clip", () => {
  const one = [kf(5, 10, 10)];
  assert.deepEqual(openSpanAround(one, 5, 12), [[5, 12]], "on the keyframe: forward");
  assert.deepEqual(openSpanAround(one, 9, 12), [[5, 12]]);
  assert.deepEqual(openSpanAround(one, 2, 12), [[-1, 5]], "before it: backward");
  assert.deepEqual(openSpans(one, 12), [[-1, 5], [5, 12]]);
  assert.deepEqual(openSpanAround([kf(11, 1, 1)], 11, 12), [], "nothing after the last frame");
  assert.deepEqual(openSpans([kf(0, 1, 1), kf(11, 1, 1)], 12), []);
  const hidden = [kf(3, 1, 1), kf(4, 2, 2, "tracked"), kf(6, 2, 2, "placed", false)];
  assert.deepEqual(openSpanAround(hidden, 8, 12), [], "an occluded last anchor: nothing");
  assert.deepEqual(openSpanAround(hidden, 1, 12), [[-1, 3]]);
  assert.deepEqual(openSpanAround([kf(0, 1, 1), kf(6, 1, 1)], 3, 12), [], "between two");
});

test("proposalRequest asks to follow the open spans and keeps the range in the clip", () => {
  const keyframes = new Map([[0, [kf(4, 1, 2)]], [1, [kf(6, 3, 4), kf(9, 3, 4)]]]);
  const body = proposalRequest(new Map([[0, [[-1, 4], [4, 12]]], [1, [[6, 9]]]]),
    (p) => keyframes.get(p), 12);
  assert.deepEqual(body, {
    tracks: [{ point: 0, keyframes: [[4, 1, 2, 1]] },
      { point: 1, keyframes: [[6, 3, 4, 1], [9, 3, 4, 1]] }],
    first_frame: 0, last_frame: 11,
    follow: [{ point: 0, direction: "backward" }, { point: 0, direction: "forward" }],
  });
});

test("acceptViewed takes the viewed held frames; the rest stays a proposal", () => {
  const proposal = { point: 0, first: 0, last: 7, spans: [[2, 8]],
    xy: [null, null, null, [3, 3], [4, 4], null, [6, 6], [7, 7]],
    ok: [false, false, false, true, true, false, true, true] };
  const keyframes = [kf(2, 2, 2), kf(5, 5, 5, "tracked")];
  const viewed = new Set([3, 7]);
  const first = acceptViewed(keyframes, proposal, (f) => viewed.has(f));
  assert.deepEqual(first.entries, [
    { frame: 3, x: 3, y: 3, visible: true, source: "tracked" },
    { frame: 5, remove: true },
    { frame: 7, x: 7, y: 7, visible: true, source: "tracked" },
  ]);
  assert.deepEqual([first.taken, first.skipped], [2, 2]);
  assert.deepEqual(heldFrames(first.rest), [4, 6]);
  viewed.add(4).add(6);
  const after = [kf(2, 2, 2), kf(3, 3, 3, "tracked"), kf(7, 7, 7, "tracked")];
  const second = acceptViewed(after, first.rest, (f) => viewed.has(f));
  assert.deepEqual(second.entries.map((e) => e.frame), [4, 6],
    "the frames already taken are neither written again nor removed");
  assert.deepEqual([second.taken, second.skipped, second.rest], [2, 0, null]);
});

test("ViewedFrames: per point and frame, cleared for new proposals", () => {
  const viewed = new ViewedFrames();
  viewed.mark(3, [0, 2]);
  viewed.mark(4, [0]);
  assert.deepEqual([viewed.has(0, 3), viewed.has(2, 3), viewed.has(2, 4), viewed.has(1, 3)],
    [true, true, false, false]);
  assert.equal(viewed.count(0), 2);
  viewed.clear();
  assert.equal(viewed.has(0, 3), false);
});

test("stopText says where a followed point stopped and why", () => {
  const stop = { point: 0, direction: "forward", from_frame: 2, reached: 31, stopped: "lost" };
  assert.equal(stopText(stop, 72), "tracked to frame 31; stopped: lost the point");
  assert.equal(stopText({ ...stop, reached: 71, stopped: "end" }, 72),
    "tracked to frame 71; stopped: reached the end of the clip");
  assert.equal(stopText({ ...stop, direction: "backward", reached: 0, stopped: "end" }, 72),
    "tracked back to frame 0; stopped: reached the start of the clip");
  assert.equal(stopText({ ...stop, stopped: "left_image" }, 72),
    "tracked to frame 31; stopped: the point left the image");
});

/** A page's assistance on a real store; the proposals route answers from `track`. */
function newAssist(track, { suggestions = null } = {}) {
  const store = new AnnotationStore({ numPoints: 2, numFrames: 12, width: 640, height: 480 });
  const calls = [];
  const api = {
    async proposals(body) {
      calls.push(body);
      const first = body.first_frame;
      const last = body.last_frame;
      return {
        first_frame: first, last_frame: last,
        points: body.tracks.map(({ point, keyframes }) => {
          const frames = Array.from({ length: last - first + 1 }, (_, i) => first + i);
          const keyed = new Set(keyframes.map((r) => r[0]));
          const xy = frames.map((f) => (keyed.has(f) ? null : track(point, f, keyframes)));
          return { point, xy, ok: xy.map(Boolean), fb_error: xy.map(() => 0.1) };
        }),
      };
    },
    async suggestions() {
      return suggestions || { available: false, reason: "needs 2 other views", views: [] };
    },
  };
  const where = { frame: 5, active: 0 };
  const assist = new Assist({ store, api, editable: () => true, where: () => where,
    onChange: () => {}, retrackDelayMs: 1 });
  return { store, assist, calls, where };
}

/** The worker steps through every frame of the clip with these points drawn. */
const stepThrough = (assist, points = [0, 1]) => {
  for (let f = 0; f < assist.store.numFrames; f++) assist.noteViewed(f, points);
};

const settle = async (assist) => {
  for (let i = 0; i < 100 && assist.pending; i++) await new Promise((r) => setTimeout(r, 5));
  assert.equal(assist.pending, false);
};

test("Track then Accept writes tracked keyframes in one undo step; lost frames stay", async () => {
  // The tracker holds at every frame but 7; positions x = 10 f.
  const { store, assist, calls } = newAssist((p, f) => (f === 7 ? null : [10 * f, 50]));
  store.placePoint(0, 0, 0, 50);
  store.placePoint(0, 11, 110, 50);
  assert.equal(await assist.track(false), true);
  assert.deepEqual(calls[0], { tracks: [{ point: 0, keyframes: [[0, 0, 50, 1], [11, 110, 50, 1]] }],
    first_frame: 0, last_frame: 11 });
  assert.equal(assist.status.text, "9 of 10 frames tracked; 1 left to interpolation (cyan " +
    "rings). Step through them: Enter accepts the frames you have viewed, Esc discards.");
  assert.deepEqual(assist.layer(5, 0).ghosts[0].xy, [50, 50]);
  assert.deepEqual(assist.timelineMarks()[0].frames, [1, 2, 3, 4, 5, 6, 8, 9, 10]);
  assert.equal(store.keyframes(0).length, 2, "nothing written before Accept");
  stepThrough(assist);
  assert.equal(assist.accept(), true);
  const keyframes = store.keyframes(0);
  assert.deepEqual(keyframes.map((k) => k.frame), [0, 1, 2, 3, 4, 5, 6, 8, 9, 10, 11]);
  assert.deepEqual(keyframes.map((k) => k.source),
    ["placed", ...Array(9).fill("tracked"), "placed"]);
  assert.equal(assist.proposals, null);
  store.undo();
  assert.equal(store.keyframes(0).length, 2, "one undo takes the whole span back");
});

test("Escape's discard writes nothing; read-only pages never track", async () => {
  const { store, assist } = newAssist((p, f) => [f, f]);
  store.placePoint(0, 0, 0, 0);
  store.placePoint(0, 10, 10, 10);
  await assist.track(false);
  assert.equal(assist.discard(), true);
  assert.equal(assist.accept(), false);
  assert.equal(store.keyframes(0).length, 2);
  assist.editable = () => false;
  assert.equal(await assist.track(false), false);
});

test("proposals of a point whose keyframes change are dropped, not written", async () => {
  const { store, assist } = newAssist((p, f) => [f, f]);
  for (const p of [0, 1]) {
    store.placePoint(p, 0, 0, 0);
    store.placePoint(p, 10, 10, 10);
  }
  await assist.track(true);
  assert.deepEqual(assist.proposals.points.map((p) => p.point), [0, 1]);
  store.placePoint(1, 10, 20, 20);
  assert.deepEqual(assist.proposals.points.map((p) => p.point), [0]);
  assert.match(assist.status.text, /press T to track it again/);
  store.undo();
  stepThrough(assist);
  assist.accept();
  assert.equal(store.keyframes(0).length, 12, "frames 1-9, and 11 followed past frame 10");
  assert.equal(store.keyframes(1).length, 2);
});

test("a correction inside a tracked run re-tracks both sides from it, once", async () => {
  // The tracker interpolates linearly between the anchors it is given.
  const linear = (p, f, rows) => {
    const before = rows.filter((r) => r[0] < f).at(-1);
    const after = rows.find((r) => r[0] > f);
    if (!before || !after) return null;
    const t = (f - before[0]) / (after[0] - before[0]);
    return [before[1] + t * (after[1] - before[1]), before[2] + t * (after[2] - before[2])];
  };
  const { store, assist, calls } = newAssist(linear);
  store.placePoint(0, 0, 0, 100);
  store.placePoint(0, 10, 100, 100);
  await assist.track(false);
  stepThrough(assist);
  assist.accept();
  assert.equal(store.keyframeAt(0, 5).x, 50);
  // The worker drags frame 5 up by 20 px: it becomes "edited", then frames 1-4 and 6-9 follow.
  store.setKeyframe(0, 5, { x: 50, y: 80, visible: true }, { gesture: 1 });
  assert.equal(store.keyframeAt(0, 5).source, "edited");
  await settle(assist);
  assert.equal(calls.length, 2);
  assert.deepEqual(calls[1].tracks[0].keyframes, [[0, 0, 100, 1], [5, 50, 80, 1], [10, 100, 100, 1]]);
  assert.deepEqual([calls[1].first_frame, calls[1].last_frame], [0, 10]);
  assert.equal(store.keyframeAt(0, 3).y, 88);
  assert.equal(store.keyframeAt(0, 7).y, 88);
  assert.equal(store.keyframeAt(0, 3).source, "tracked");
  // The worker's actions: 2 placements, Enter, the drag; the page's own re-track is none.
  assert.equal(store.actionCount, 4);
  assert.equal(store.editCount, 5);
  store.undo();
  assert.equal(store.actionCount, 5, "an undo is the worker's");
  assert.equal(store.keyframeAt(0, 3).y, 100, "the re-track is its own undo step");
  assert.equal(store.keyframeAt(0, 5).y, 80);
  await settle(assist);
  assert.equal(calls.length, 2, "undo does not re-track");
});

test("suggestions: a quiet reason, or prefilled keyframes around the hand-set ones", async () => {
  const none = newAssist(() => null);
  await none.assist.loadSuggestions();
  assert.equal(none.assist.suggestNote, "needs 2 other views");
  assert.equal(none.assist.useSuggestions(true), false);

  const xy = Array.from({ length: 12 }, (_, f) => [100 + f, 200]);
  const visible = Array.from({ length: 12 }, (_, f) => (f === 6 ? false : null));
  const { store, assist, where } = newAssist(() => null, { suggestions: {
    available: true, reason: null, views: ["cam-a", "cam-b", "cam-c"], min_views: 2,
    points: [{ point: 0, xy, visible }], epipolar: [] } });
  await assist.loadSuggestions();
  assert.match(assist.suggestNote, /^Suggestions from 3 other views \(magenta rings\)\. U: this point/);
  store.placePoint(0, 0, 90, 190);
  assert.deepEqual(assist.layer(3, 0).suggestion, { point: 0, xy: [103, 200], visible: true });
  where.active = 0;
  assert.equal(assist.useSuggestions(false), true);
  const keyframes = store.keyframes(0);
  assert.equal(keyframes.length, 12);
  assert.deepEqual([keyframes[0].x, keyframes[0].source], [90, "placed"]);
  assert.deepEqual([keyframes[6].visible, keyframes[6].x, keyframes[6].source],
    [false, 106, "prefilled"]);
  assert.equal(assist.layer(3, 0).suggestion, null, "a used suggestion is no longer a ghost");
});

test("suggestions fitted from one view say so", async () => {
  const xy = Array.from({ length: 4 }, () => [100, 200]);
  const { assist } = newAssist(() => null, { suggestions: {
    available: true, reason: null, views: ["cam-a"], min_views: 1, method: "fitted",
    points: [{ point: 0, xy, visible: [true, true, false, null] }], epipolar: [] } });
  await assist.loadSuggestions();
  assert.match(assist.suggestNote,
    /^Suggestions from 1 other view, fitted: check each \(magenta rings\)/);
  assert.equal(assist.suggestions.size, 1);
});

test("Track all: Accept writes every point in one undo step and one change", async () => {
  const { store, assist, calls } = newAssist((p, f) => [10 * f + p, 50 + p]);
  for (const p of [0, 1]) {
    store.placePoint(p, 0, p, 50 + p);
    store.placePoint(p, 11, 110 + p, 50 + p);
  }
  const before = store.toJSON();
  assert.equal(await assist.track(true), true);
  assert.deepEqual(calls[0].tracks.map((t) => t.point), [0, 1]);
  const seen = [];
  store.subscribe((change) => seen.push(change));
  stepThrough(assist);
  assert.equal(assist.accept(), true);
  assert.equal(seen.length, 1);
  assert.deepEqual([seen[0].label, seen[0].point, seen[0].points],
    ["accept tracking", null, [0, 1]]);
  assert.deepEqual(seen[0].created, [1, 2, 3, 4, 5, 6, 7, 8, 9, 10]);
  for (const p of [0, 1]) {
    assert.deepEqual(store.keyframes(p).map((k) => k.source),
      ["placed", ...Array(10).fill("tracked"), "placed"]);
    assert.deepEqual([store.keyframeAt(p, 4).x, store.keyframeAt(p, 4).y], [40 + p, 50 + p]);
  }
  const after = store.toJSON();
  assert.equal(store.undo(), true);
  assert.deepEqual(store.toJSON(), before, "one undo takes both points' spans back");
  assert.deepEqual(seen[1].points, [0, 1]);
  assert.equal(store.redo(), true);
  assert.deepEqual(store.toJSON(), after);
  await settle(assist);
  assert.equal(calls.length, 1, "accepting, undoing and redoing re-track nothing");
});

test("Shift+U: every point's suggestions in one undo step", async () => {
  const xy = (p) => Array.from({ length: 12 }, (_, f) => [100 + f, 200 + p]);
  const visible = Array(12).fill(null);
  const { store, assist } = newAssist(() => null, { suggestions: {
    available: true, reason: null, views: ["cam-a", "cam-b", "cam-c"], min_views: 3,
    points: [0, 1].map((p) => ({ point: p, xy: xy(p), visible })), epipolar: [] } });
  await assist.loadSuggestions();
  store.placePoint(1, 3, 5, 5);
  const before = store.toJSON();
  const seen = [];
  store.subscribe((change) => seen.push(change));
  assert.equal(assist.useSuggestions(true), true);
  assert.equal(assist.status.text, "Used 23 suggested keyframes for 2 points: step through " +
    "the frames and drag any that are off.");
  assert.equal(seen.length, 1);
  assert.deepEqual([seen[0].label, seen[0].points], ["use suggestions", [0, 1]]);
  assert.equal(store.keyframes(0).length, 12);
  assert.deepEqual(store.keyframeAt(1, 3), { frame: 3, x: 5, y: 5, visible: true,
    source: "placed" }, "a keyframe set by hand is kept");
  assert.equal(store.keyframeAt(1, 4).source, "prefilled");
  store.undo();
  assert.deepEqual(store.toJSON(), before);
});

test("points corrected together are re-tracked in one request and one undo step", async () => {
  // The tracker follows the anchors linearly, so a re-track shows where each anchor went.
  const linear = (p, f, rows) => {
    const before = rows.filter((r) => r[0] < f).at(-1);
    const after = rows.find((r) => r[0] > f);
    if (!before || !after) return null;
    const t = (f - before[0]) / (after[0] - before[0]);
    return [before[1] + t * (after[1] - before[1]), before[2] + t * (after[2] - before[2])];
  };
  const { store, assist, calls } = newAssist(linear);
  for (const p of [0, 1]) {
    store.placePoint(p, 0, 0, 100 + p);
    store.placePoint(p, 10, 100, 100 + p);
  }
  await assist.track(true);
  stepThrough(assist);
  assist.accept();
  // A skeleton drag at frame 5: both points' tracked keyframes there move up 20 px, in steps.
  for (let step = 1; step <= 4; step++) {
    store.setPose(5, [0, 1].map((p) => ({ point: p, x: 50, y: 100 + p - 5 * step,
      visible: true })), { gesture: "skeleton" });
  }
  assert.equal(store.keyframeAt(1, 5).source, "edited");
  await settle(assist);
  assert.equal(calls.length, 2, "one re-track request for both points");
  assert.deepEqual(calls[1].tracks.map((t) => t.point), [0, 1]);
  assert.deepEqual(calls[1].tracks[1].keyframes, [[0, 0, 101, 1], [5, 50, 81, 1],
    [10, 100, 101, 1]]);
  assert.match(assist.status.text, /^Re-tracked frames 0-10 around your corrections of 2 points/);
  assert.deepEqual([store.keyframeAt(0, 3).y, store.keyframeAt(1, 7).y], [88, 89]);
  const dragged = [0, 1].map((p) => store.keyframeAt(p, 5));
  store.undo();
  assert.deepEqual([store.keyframeAt(0, 3).y, store.keyframeAt(1, 7).y], [100, 101],
    "one undo takes both re-tracks back");
  assert.deepEqual([0, 1].map((p) => store.keyframeAt(p, 5)), dragged,
    "and leaves the drag itself");
  await settle(assist);
  assert.equal(calls.length, 2);
});

/** A tracker that follows x = 10 f from frame `from` up to frame `stop`, and says so. */
function followingApi(stop) {
  const calls = [];
  return { calls, async proposals(body) {
    calls.push(body);
    const first = body.first_frame;
    const frames = Array.from({ length: body.last_frame - first + 1 }, (_, i) => first + i);
    const from = body.tracks[0].keyframes.at(-1)[0];
    const xy = frames.map((f) => (f > from && f <= stop ? [10 * f, 50] : null));
    return { first_frame: first, last_frame: body.last_frame,
      points: [{ point: 0, xy, ok: xy.map(Boolean), fb_error: xy.map(() => 0.1) }],
      stops: [{ point: 0, direction: "forward", from_frame: from, reached: stop,
        stopped: "lost" }] };
  }, async suggestions() { return { available: false, views: [] }; } };
}

test("T past a single keyframe follows it forward; Enter takes only the frames viewed", async () => {
  const store = new AnnotationStore({ numPoints: 1, numFrames: 12, width: 640, height: 480 });
  const api = followingApi(8);
  const where = { frame: 2, active: 0 };
  const assist = new Assist({ store, api, editable: () => true, where: () => where,
    onChange: () => {} });
  store.placePoint(0, 2, 20, 50);
  assert.equal(await assist.track(false), true);
  assert.deepEqual(api.calls[0], { tracks: [{ point: 0, keyframes: [[2, 20, 50, 1]] }],
    first_frame: 2, last_frame: 11, follow: [{ point: 0, direction: "forward" }] });
  assert.match(assist.status.text, /^Tracked to frame 8; stopped: lost the point\. 6 of 6 frames/);
  assert.deepEqual(assist.stopMarks(), [{ point: 0, frame: 8, direction: "forward",
    stopped: "lost" }]);
  // The worker steps to frames 3-5 only, then presses Enter.
  for (const f of [3, 4, 5]) assist.noteViewed(f, [0]);
  assert.equal(assist.accept(), true);
  assert.deepEqual(store.keyframes(0).map((k) => [k.frame, k.source]),
    [[2, "placed"], [3, "tracked"], [4, "tracked"], [5, "tracked"]]);
  assert.match(assist.status.text, /^Accepted 3 tracked frames you have viewed; 3 not yet viewed/);
  assert.deepEqual(assist.timelineMarks()[0].frames, [6, 7, 8], "the rest still shown");
  for (const f of [6, 7, 8]) assist.noteViewed(f, [0]);
  assert.equal(assist.accept(), true);
  assert.deepEqual(store.keyframes(0).map((k) => k.frame), [2, 3, 4, 5, 6, 7, 8]);
  assert.equal(assist.proposals, null);
  assert.equal(store.keyframeAt(0, 6).x, 60);
});

test("O on a tracked frame keeps every tracked keyframe on both sides; O again too", async () => {
  const { store, assist, calls } = newAssist((p, f) => [10 * f, 50]);
  store.placePoint(0, 0, 0, 50);
  store.placePoint(0, 10, 100, 50);
  await assist.track(false);
  stepThrough(assist);
  assist.accept();
  const tracked = () => store.keyframes(0).filter((k) => k.source === "tracked").length;
  assert.equal(tracked(), 9);
  assert.equal(store.toggleVisibility(0, 5), true);
  await settle(assist);
  assert.equal(calls.length, 1, "a toggle re-tracks nothing");
  assert.deepEqual([store.keyframeAt(0, 5).visible, tracked()], [false, 8]);
  assert.equal(store.valueAt(0, 6).visible, true, "visible again after the toggled frame");
  store.toggleVisibility(0, 5);
  await settle(assist);
  assert.deepEqual([store.keyframeAt(0, 5).visible, store.keyframeAt(0, 5).x, tracked()],
    [true, 50, 8]);
  assert.equal(calls.length, 1);
});

test("suggestions being prepared: the reason shows, then the page asks again", async () => {
  const xy = Array.from({ length: 4 }, () => [100, 200]);
  const answers = [
    { available: false, preparing: true, views: ["cam-a"], points: [], epipolar: [],
      reason: "suggestions from the hand model are being prepared; they will appear shortly" },
    { available: false, preparing: true, views: ["cam-a"], points: [], epipolar: [],
      reason: "suggestions from the hand model are being prepared; they will appear shortly" },
    { available: true, reason: null, views: ["cam-a"], min_views: 1, method: "fitted",
      points: [{ point: 0, xy, visible: [true, true, true, true] }], epipolar: [] },
  ];
  const notes = [];
  let asked = 0;
  const api = { async suggestions() { return answers[Math.min(asked++, answers.length - 1)]; } };
  const store = new AnnotationStore({ numPoints: 2, numFrames: 4, width: 640, height: 480 });
  const assist = new Assist({ store, api, editable: () => true,
    where: () => ({ frame: 0, active: 0 }), onChange: () => notes.push(assist.suggestNote),
    suggestPollMs: 1 });
  await assist.loadSuggestions();
  assert.equal(asked, 3);
  assert.equal(notes[0], answers[0].reason);
  assert.match(assist.suggestNote, /^Suggestions from 1 other view, fitted: check each/);
  assert.equal(assist.suggestions.size, 1);

  // A job that never finishes: the page stops asking after its limit and says so.
  let polls = 0;
  const stuck = new Assist({ store, api: { async suggestions() { polls++; return answers[0]; } },
    editable: () => true, where: () => ({ frame: 0, active: 0 }), onChange: () => {},
    suggestPollMs: 1, suggestPollLimitMs: 20 });
  await stuck.loadSuggestions();
  assert.ok(polls >= 2 && polls < 100, String(polls));
  assert.match(stuck.suggestNote, /taking longer than expected/);
  assert.equal(stuck.suggestions.size, 0);
});

/** A hand page's assistance whose model-follow route answers `answers` in turn (the last one
 * again once they run out). */
function modelAssist(answers, { numFrames = 12, numPoints = 2 } = {}) {
  const store = new AnnotationStore({ numPoints, numFrames, width: 640, height: 480 });
  const calls = [];
  const api = {
    async proposals() { throw new Error("not asked"); },
    async suggestions() { return { available: false, reason: "none", views: [] }; },
    async modelFollow(body) {
      calls.push(body);
      return answers[Math.min(calls.length - 1, answers.length - 1)];
    },
  };
  const where = { frame: 3, active: 0 };
  const assist = new Assist({ store, api, editable: () => true, where: () => where,
    onChange: () => {}, handModel: true, suggestPollMs: 1, suggestPollLimitMs: 200 });
  return { store, assist, calls, where };
}

/** A follow of 2 points over 12 frames from frame 3, reaching frames 0-8. */
const FOLLOWED = {
  available: true, preparing: false, reason: null, start_frame: 3, first_frame: 0,
  last_frame: 11,
  points: [0, 1].map((point) => {
    const xy = Array.from({ length: 12 }, (_, f) => (f <= 8 && f !== 3 ? [10 * f, 20 + point] : null));
    return { point, xy, ok: xy.map(Boolean) };
  }),
  stops: [{ direction: "forward", reached: 8, stopped: "depth" },
    { direction: "backward", reached: 0, stopped: "end" }],
};

test("followModel: waits while the server prepares, then shows the follow as proposals", async () => {
  const preparing = { available: false, preparing: true,
    reason: "the hand model is following the hand through this view's depth" };
  const { store, assist, calls } = modelAssist([preparing, preparing, FOLLOWED]);
  store.placePoint(0, 3, 30, 20);
  store.placePoint(1, 3, 30, 21);
  store.placePoint(1, 10, 99, 21);
  store.setTracks([{ point: 1, entries: [{ frame: 6, x: 1, y: 1, visible: true,
    source: "tracked" }] }], { label: "t" });
  assert.equal(await assist.followModel(), true);
  assert.equal(calls.length, 3);
  // Every ask carries every keyframe, accepted proposals too, the same body each time; no
  // begin (no frame before this one has 6 joints keyed).
  assert.deepEqual(calls[0], { tracks: [{ point: 0, keyframes: [[3, 30, 20, 1]] },
    { point: 1, keyframes: [[3, 30, 21, 1], [6, 1, 1, 1], [10, 99, 21, 1]] }] });
  assert.deepEqual(calls[2], calls[0]);
  assert.equal(assist.status.kind, "info");
  assert.equal(assist.status.text, "The hand model followed frames 0-8 from your keyframes on " +
    "frame 3; it lost the hand after frame 8 (the depth there no longer fits it). Cyan rings: " +
    "step through them from frame 3; Enter accepts the frames you have viewed, Esc discards. " +
    "Drag any ring that is off; where a few come off together, accept up to that frame, drag " +
    "them there and press M again to follow on.");
  assert.deepEqual(assist.layer(5, 0).ghosts[0].xy, [50, 20]);
  assert.equal(assist.layer(9, 0).ghosts[0].xy, null);
  assert.deepEqual(assist.timelineMarks()[0].frames, [0, 1, 2, 4, 5, 6, 7, 8]);
  // The worker steps from frame 3 to frame 6 and accepts: those frames only, nothing removed.
  for (const f of [4, 5, 6]) assist.noteViewed(f, [0, 1]);
  assert.equal(assist.accept(), true);
  assert.deepEqual(store.keyframes(0).map((k) => [k.frame, k.source || "placed"]),
    [[3, "placed"], [4, "tracked"], [5, "tracked"], [6, "tracked"]]);
  assert.deepEqual(store.keyframes(1).map((k) => [k.frame, k.x, k.source || "placed"]),
    [[3, 30, "placed"], [4, 40, "tracked"], [5, 50, "tracked"], [6, 60, "tracked"],
      [10, 99, "placed"]]);
  assert.match(assist.status.text, /^Accepted 6 tracked frames you have viewed; 10 not yet viewed/);
  assert.equal(assist.proposals.points.length, 2, "the unviewed frames stay proposals");
  // Stepping on and pressing Enter again takes the rest; the tracked keyframe at frame 6 of
  // point 1 was replaced, frame 10's anchor is untouched.
  for (let f = 0; f <= 8; f++) assist.noteViewed(f, [0, 1]);
  assert.equal(assist.accept(), true);
  assert.equal(assist.proposals, null);
  assert.deepEqual(store.keyframes(0).map((k) => k.frame), [0, 1, 2, 3, 4, 5, 6, 7, 8]);
  assert.deepEqual(store.keyframes(1).map((k) => k.frame), [0, 1, 2, 3, 4, 5, 6, 7, 8, 10]);
});

test("followModel: asked again after a frame keyed whole, it follows on from the frame shown", async () => {
  const { store, assist, calls, where } = modelAssist([FOLLOWED, FOLLOWED, FOLLOWED],
    { numPoints: 21 });
  for (let p = 0; p < 6; p++) store.placePoint(p, 2, 10 + p, 20);
  where.frame = 2;
  await assist.followModel();
  assert.equal(calls[0].begin, undefined, "from the keyed frame itself: both ways");
  where.frame = 7;
  await assist.followModel();
  assert.equal(calls[1].begin, 7, "a correction on frame 7: forward from there");
  store.toggleVisibility(0, 2);
  assist.proposals = null;
  await assist.followModel();
  assert.equal(calls[2].begin, undefined, "5 visible joints on frame 2 start nothing");
});

test("handKeyedBefore counts visible placed joints per earlier frame", () => {
  const rows = (f, visible) => ({ keyframes: [[f, 1, 1, visible]] });
  const six = Array.from({ length: 6 }, () => rows(4, 1));
  assert.equal(handKeyedBefore(six, 5), true);
  assert.equal(handKeyedBefore(six, 4), false);
  assert.equal(handKeyedBefore([...six.slice(1), rows(4, 0)], 5), false);
  assert.equal(handKeyedBefore([...six.slice(1), { keyframes: [[4, null, null, 1]] }], 5), false);
});

test("followModel: says why nothing is shown, and gives up waiting after the limit", async () => {
  const refused = { available: false, preparing: false,
    reason: "place at least 6 visible joints on one frame first: the hand model starts from " +
      "that frame" };
  let { assist } = modelAssist([refused]);
  assert.equal(await assist.followModel(), false);
  assert.equal(assist.status.kind, "warn");
  assert.equal(assist.status.text, "Place at least 6 visible joints on one frame first: the " +
    "hand model starts from that frame.");
  assert.equal(assist.proposals, null);
  ({ assist } = modelAssist([{ available: false, preparing: true, reason: "busy" }]));
  assert.equal(await assist.followModel(), false);
  assert.match(assist.status.text, /taking longer than expected: press M again/);
  assert.equal(assist.pending, false);
  ({ assist } = modelAssist([{ ...FOLLOWED, points: FOLLOWED.points.map((p) => (
    { ...p, ok: p.ok.map(() => false) })) }]));
  assert.equal(await assist.followModel(), false);
  assert.equal(assist.status.text, "The hand model proposes nothing beyond your keyframes here.");
});

test("followModel: offered on hand pages only", async () => {
  const store = new AnnotationStore({ numPoints: 2, numFrames: 12, width: 640, height: 480 });
  const api = { async proposals() {}, async suggestions() {}, async modelFollow() {
    throw new Error("not asked"); } };
  const assist = new Assist({ store, api, editable: () => true,
    where: () => ({ frame: 0, active: 0 }), onChange: () => {} });
  assert.equal(assist.handModel, false);
  assert.equal(await assist.followModel(), false);
});

test("modelText: the whole clip, and a follow stopped both ways", () => {
  const whole = { ...FOLLOWED, stops: [{ direction: "forward", reached: 11, stopped: "end" },
    { direction: "backward", reached: 0, stopped: "end" }] };
  assert.match(modelText(whole, 12), /^The hand model followed frames 0-11 \(the whole clip\) from your keyframes on frame 3\. /);
  const both = { ...FOLLOWED, stops: [{ direction: "forward", reached: 8, stopped: "depth" },
    { direction: "backward", reached: 2, stopped: "depth" }] };
  assert.match(modelText(both, 12), /frames 2-8 from your keyframes on frame 3; it lost the hand after frame 8 and before frame 2 \(/);
  assert.deepEqual(modelProposals(FOLLOWED, 12).map((p) => [p.point, p.spans, p.partial]),
    [[0, [[-1, 12]], true], [1, [[-1, 12]], true]]);
});
