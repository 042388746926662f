import assert from "node:assert/strict";
import { test } from "node:test";

import {
  FRAME_COST_COLUMNS, frameCostCells, money, targetName,
} from "../../frontend/admin/core/cost-format.js";

const HAND = {
  target_key: "hand:0", frames: 12, frames_labelled: 10, actions: 305, seconds: 717.5,
  money: "1.26", currency: "USD", actions_per_frame: 30.5, seconds_per_frame: 71.75,
  money_per_frame: "0.1260",
};

test("a target's cost line becomes one cell per column, money with its currency", () => {
  const cells = frameCostCells(HAND, targetName(HAND.target_key));
  assert.equal(cells.length, FRAME_COST_COLUMNS.length);
  assert.deepEqual(cells, ["hand 0", "10 of 12", "305", "717.5 s", "1.26 USD", "30.50",
    "71.75", "0.1260 USD"]);
});

test("a target without a labelled frame shows a dash per frame, not a division by zero", () => {
  const none = { ...HAND, frames_labelled: 0, actions_per_frame: null, seconds_per_frame: null,
    money_per_frame: null };
  assert.deepEqual(frameCostCells(none, "hand 0").slice(5), ["–", "–", "–"]);
});

test("target keys read as people name them", () => {
  assert.equal(targetName("object:1", ["002_master_chef_can", "003_cracker_box"]),
    "object 1 (003_cracker_box)");
  assert.equal(targetName("object:2"), "object 2");
  assert.equal(targetName("total"), "total");
  assert.equal(money("0.4500", "GBP"), "0.4500 GBP");
});
