import assert from "node:assert/strict";
import { test } from "node:test";

import {
  PROVIDERS, freePlaces, placesLine, workerName,
} from "../../frontend/admin/core/crowd-format.js";

test("freePlaces leaves out work decided, submitted or being done, never below zero", () => {
  assert.equal(freePlaces({ places: 5, decided: 1, submitted: 1, holders: 1 }), 2);
  assert.equal(freePlaces({ places: 1, decided: 1, submitted: 0, holders: 2 }), 0);
});

test("placesLine says how a unit's places are taken, none free once it expired", () => {
  const unit = { places: 3, decided: 1, submitted: 0, holders: 1, state: "open" };
  assert.equal(placesLine(unit),
    "3 places: 1 decided, 0 submitted, 1 being worked on, 1 free");
  assert.match(placesLine({ ...unit, places: 1, state: "expired" }),
    /^1 place: .*none free \(expired\)$/);
});

test("workerName puts a portal account's email beside the provider's worker id", () => {
  assert.equal(workerName("A1B2C3", "member@example.org"), "A1B2C3 · member@example.org");
  assert.equal(workerName("A1B2C3", null), "A1B2C3");
});

test("PROVIDERS names each provider the API takes", () => {
  assert.deepEqual(PROVIDERS.map(([key]) => key), ["mturk", "prolific", "team"]);
});
