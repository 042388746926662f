/**
 * What the admin page says about the crowd: a unit of work's places, a worker's portal
 * account, the providers a task is published to. Pure functions, no DOM.
 */

/** The providers a task can be published to, as the API names them, with their names for
 * people. */
export const PROVIDERS = [
  ["mturk", "MTurk-compatible marketplace"],
  ["prolific", "Prolific"],
  ["team", "Our team (portal)"],
];

/**
 * Places of a unit not yet taken: its places less the work decided, submitted or being done.
 * @param {{places: number, decided: number, holders: number, submitted: number}} unit
 */
export function freePlaces(unit) {
  return Math.max(unit.places - unit.decided - unit.submitted - unit.holders, 0);
}

/**
 * One line about a unit's places, for its row's tooltip.
 * @param {{places: number, decided: number, holders: number, submitted: number,
 *          state: string}} unit
 */
export function placesLine(unit) {
  const free = unit.state === "open" ? `${freePlaces(unit)} free` : "none free (expired)";
  return `${unit.places} place${unit.places === 1 ? "" : "s"}: ${unit.decided} decided, `
    + `${unit.submitted} submitted, ${unit.holders} being worked on, ${free}`;
}

/**
 * A worker as people know them: the provider's worker id, and the portal account's email
 * beside it where the worker is a portal account.
 * @param {string} workerId  @param {string|null|undefined} email
 */
export function workerName(workerId, email) {
  return email ? `${workerId} · ${email}` : workerId;
}
