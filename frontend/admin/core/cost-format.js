/**
 * The cost of a labelled 3D frame as the admin page shows it (GET /api/frame-costs): a row
 * per target and the sequence's total. Pure functions, no DOM.
 */

const NONE = "–";

/** The columns of a sequence's table: [field, title]. */
export const FRAME_COST_COLUMNS = [
  ["target", "Target"], ["frames_labelled", "3D frames labelled"], ["actions", "Actions"],
  ["seconds", "Working time"], ["money", "Spent"], ["actions_per_frame", "Actions / frame"],
  ["seconds_per_frame", "Seconds / frame"], ["money_per_frame", "Spent / frame"],
];

/**
 * A target key as people read it: "hand:0" -> "hand 0", "object:1" -> "object 1 (name)".
 * @param {string} key  @param {string[]} [objectNames]  the sequence's objects by index
 */
export function targetName(key, objectNames = []) {
  const [kind, index] = key.split(":");
  if (kind === "object" && objectNames[Number(index)]) {
    return `object ${index} (${objectNames[Number(index)]})`;
  }
  return index === undefined ? key : `${kind} ${index}`;
}

/**
 * An amount (a decimal string as the API gives it) with its currency: "0.4500 USD".
 * @param {string | null} amount  @param {string} currency
 */
export function money(amount, currency) {
  return amount === null || amount === undefined ? NONE : `${amount} ${currency}`;
}

/** @param {number | null} value @param {number} digits */
function number(value, digits) {
  return value === null || value === undefined ? NONE : value.toFixed(digits);
}

/**
 * One line (a target, or the total) as the table's cells, in FRAME_COST_COLUMNS' order.
 * @param {any} line  a TargetFrameCost  @param {string} name  what the first cell says
 */
export function frameCostCells(line, name) {
  return [name, `${line.frames_labelled} of ${line.frames}`, String(line.actions),
    `${number(line.seconds, 1)} s`, money(line.money, line.currency),
    number(line.actions_per_frame, 2), number(line.seconds_per_frame, 2),
    money(line.money_per_frame, line.currency)];
}
