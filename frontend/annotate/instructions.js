/**
 * The instructions panel: what to mark, a diagram of the 21 hand joints in DexYCB order, and
 * good/bad examples (text + small drawings). For object tasks: how to pick the two landmarks.
 * Static content only; point names and colours come from the task.
 */

const SVG_NS_ATTR = 'xmlns="http://www.w3.org/2000/svg"';

/** @param {string} text */
export function escapeHtml(text) {
  return String(text).replace(/[&<>"']/g, (c) => (
    { "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;" }[c]));
}

/**
 * "index_pip" -> "Index PIP", "wrist" -> "Wrist", "landmark_1" -> "Landmark 1".
 * @param {string} name
 */
export function displayName(name) {
  return name.split("_").map((part, i) => {
    if (["mcp", "pip", "dip"].includes(part)) return part.toUpperCase();
    return i === 0 ? part.charAt(0).toUpperCase() + part.slice(1) : part;
  }).join(" ");
}

/**
 * What the page calls each point: hand joints with their number in the diagram ("8 Index tip"),
 * object landmarks by name alone ("Landmark 1"; their keys are 1 and 2).
 * @param {{kind: string, point_names: string[]}} task
 * @returns {string[]}
 */
export function pointLabels(task) {
  return task.point_names.map((name, i) =>
    (task.kind === "hand" ? `${i} ${displayName(name)}` : displayName(name)));
}

/**
 * Diagram positions (SVG units) of the 21 joints of a right hand seen from the back, DexYCB
 * order: wrist, then thumb, index, middle, ring, little, each mcp, pip, dip, tip.
 */
export function diagramJoints() {
  const joints = [[130, 282]];
  const fingers = [
    { base: [92, 236], dir: -2.2, lengths: [38, 30, 24] },
    { base: [98, 150], dir: -1.75, lengths: [40, 26, 22] },
    { base: [128, 142], dir: -1.58, lengths: [44, 28, 23] },
    { base: [157, 148], dir: -1.42, lengths: [40, 26, 21] },
    { base: [182, 166], dir: -1.25, lengths: [31, 21, 19] },
  ];
  for (const { base, dir, lengths } of fingers) {
    let [x, y] = base;
    joints.push([x, y]);
    for (const len of lengths) {
      x += len * Math.cos(dir);
      y += len * Math.sin(dir);
      joints.push([Math.round(x), Math.round(y)]);
    }
  }
  return joints;
}

/**
 * Inline SVG of the hand with every joint numbered, in the task's colours.
 * @param {string[]} colors  21 colours
 * @returns {string} SVG markup
 */
export function handDiagramSvg(colors) {
  const j = diagramJoints();
  const fingerPaths = [1, 5, 9, 13, 17].map((s) =>
    `M${j[s][0]},${j[s][1]} L${j[s + 1][0]},${j[s + 1][1]} L${j[s + 2][0]},${j[s + 2][1]} ` +
    `L${j[s + 3][0]},${j[s + 3][1]}`);
  const skin = fingerPaths.map((d) => `<path d="${d}" class="hd-skin"/>`).join("");
  const palm = `<path class="hd-palm" d="M${j[0][0] - 38},${j[0][1]} L${j[1][0]},${j[1][1]} ` +
    `L${j[5][0]},${j[5][1]} L${j[9][0]},${j[9][1] - 4} L${j[13][0]},${j[13][1]} ` +
    `L${j[17][0]},${j[17][1]} L${j[0][0] + 36},${j[0][1]} Z"/>`;
  const bones = [];
  for (let child = 1; child < 21; child++) {
    const parent = (child - 1) % 4 === 0 ? 0 : child - 1;
    bones.push(`<line x1="${j[parent][0]}" y1="${j[parent][1]}" x2="${j[child][0]}" ` +
      `y2="${j[child][1]}" stroke="${colors[child]}" class="hd-bone"/>`);
  }
  const dots = j.map(([x, y], i) => {
    const dx = i === 0 ? 12 : (i <= 4 ? -16 : 7);
    return `<circle cx="${x}" cy="${y}" r="4.5" fill="${colors[i]}" class="hd-joint"/>` +
      `<text x="${x + dx}" y="${y + 4}" class="hd-label">${i}</text>`;
  }).join("");
  return `<svg ${SVG_NS_ATTR} viewBox="0 0 260 300" class="hand-diagram" role="img" ` +
    `aria-label="The 21 hand joints, numbered in annotation order">${palm}${skin}` +
    `${bones.join("")}${dots}</svg>`;
}

/** A small finger drawing with one marker, for the examples. */
function fingerSvg(marker, extra = "") {
  return `<svg ${SVG_NS_ATTR} viewBox="0 0 120 70" class="example-svg">` +
    `<path d="M10,48 L60,40 L105,30" class="ex-finger"/>${extra}${marker}</svg>`;
}

const GOOD = '<span class="tag good">Good</span>';
const BAD = '<span class="tag bad">Bad</span>';

/** Good and bad examples for hand tasks. */
function handExamples() {
  const dot = (x, y, fill = "#31a354") =>
    `<circle cx="${x}" cy="${y}" r="5" fill="${fill}" stroke="#000" stroke-width="1"/>`;
  const dashed = '<circle cx="60" cy="40" r="6" fill="none" stroke="#31a354" ' +
    'stroke-width="2" stroke-dasharray="3 3"/><path d="M56,36 L64,44 M64,36 L56,44" ' +
    'stroke="#31a354" stroke-width="2"/>';
  return [
    [GOOD, fingerSvg(dot(60, 40)), "The point sits on the centre of the joint, inside the finger."],
    [BAD, fingerSvg(dot(58, 28)),
      "On the edge of the finger or on a skin crease: move it to the centre."],
    [GOOD, fingerSvg(dashed, '<rect x="40" y="10" width="45" height="50" class="ex-occluder"/>'),
      "Hidden behind the object: press O to mark it occluded, and leave your best guess."],
    [BAD, fingerSvg(dot(60, 40, "#3182bd")),
      "Wrong finger: an index joint (green) placed on the middle finger. Check the colours."],
  ];
}

/** Good and bad examples for object tasks. */
function objectExamples() {
  const box = '<rect x="25" y="12" width="70" height="46" class="ex-object"/>';
  const dot = (x, y, fill) =>
    `<circle cx="${x}" cy="${y}" r="5" fill="${fill}" stroke="#000" stroke-width="1"/>`;
  const svg = (inner) => `<svg ${SVG_NS_ATTR} viewBox="0 0 120 70" class="example-svg">` +
    `${box}${inner}</svg>`;
  return [
    [GOOD, svg(dot(25, 12, "#ff7f0e") + dot(95, 58, "#17becf")),
      "Two sharp corners far apart, both visible in most frames."],
    [BAD, svg(dot(60, 35, "#ff7f0e") + dot(64, 37, "#17becf")),
      "Two points close together on a plain surface: they cannot be found again."],
    [BAD, svg(dot(108, 35, "#ff7f0e")), "A point off the object, on the table or on the hand."],
  ];
}

/** @param {Array<[string, string, string]>} rows */
function examplesHtml(rows) {
  return rows.map(([tag, svg, text]) =>
    `<figure class="example">${svg}<figcaption>${tag} ${escapeHtml(text)}</figcaption></figure>`)
    .join("");
}

/**
 * How the page's suggestions work (core/assist.js): tracking proposals, pre-fill from other views,
 * epipolar lines; all of them are only ever suggestions the worker checks.
 */
const SUGGESTIONS_TEXT = "Track (T) proposes the active point's positions between your " +
  "keyframes around this frame, shown as cyan rings (Shift+T: every point through the clip). " +
  "A point you placed on one frame only is followed from there: T after it tracks forward, " +
  "T before it tracks backward, until the tracker loses the point; an orange mark on the " +
  "timeline and the status line say where it stopped. Step through the proposed frames: Enter " +
  "accepts the frames you have looked at (stepped to or played through) and leaves the others " +
  "as proposals; Esc discards them. Where other views are labelled already, a magenta ring " +
  "suggests the point's position (U uses the suggestions) and coloured lines show where each " +
  "labelled view says the point lies (E hides them). Suggestions are often right but not " +
  "always: drag any that is off; correcting a tracked frame tracks the frames around it again.";

/** The hand model's follow (hand tasks only; core/assist.js followModel). */
const MODEL_TEXT = "Follow hand (M): once you have placed at least 6 joints on one frame " +
  "(the hidden ones marked occluded), the hand model follows the hand from that frame through " +
  "the clip in the depth this camera recorded. It takes up to a minute, then shows cyan rings " +
  "as Track does and says where it lost the hand. Step outward from that frame while the rings " +
  "sit on the joints, drag any that is off, and press Enter: it accepts the frames you have " +
  "viewed. Where a few rings come off the hand, stay on that frame, press Enter, drag them " +
  "onto their joints and press M again: the model follows on from there. Where most come off " +
  "or it lost the hand, Track all (Shift+T) fills what is left.";

/**
 * The fair warning about check suggestions (worker.assist.checks): said plainly, in every
 * task's instructions, the training clip's included.
 */
const CHECKS_TEXT = "Some suggestions are placed wrong on purpose (about 15 px off the " +
  "point) to check that you look at them. Work that keeps them unchanged is reviewed or " +
  "rejected, and the feedback names those points and frames. Look at each suggestion on its " +
  "frame and drag the wrong ones onto the point before you accept.";

/**
 * Fills the instructions panel for a task.
 * @param {HTMLElement} panel
 * @param {{kind: "hand"|"object", point_names: string[], point_colors: string[],
 *          target?: string}} task  target: "right hand", "mustard bottle"
 */
export function renderInstructions(panel, task) {
  const legend = task.point_names.map((name, i) =>
    `<li><span class="swatch" style="background:${escapeHtml(task.point_colors[i])}"></span>` +
    `${i} ${escapeHtml(displayName(name))}</li>`).join("");
  const hand = task.kind === "hand";
  const intro = hand
    ? `Track the 21 joints of the ${task.target || "hand"} (named at the top of the page) ` +
      "through the clip. Place every joint on a " +
      "few keyframes (start, end, and wherever it changes direction); positions in between are " +
      "interpolated, so check them and correct any that drift. Joints hidden behind the object " +
      "or other fingers are marked occluded (O)."
    : "Step 1: pick 2 distinctive points on the highlighted object that stay visible most of " +
      "the time (corners, printed marks, sharp edges), far apart. Step 2: track them through " +
      "the clip; mark a point occluded (O) while it is hidden.";
  panel.innerHTML = `<h2>Instructions</h2><p>${escapeHtml(intro)}</p>` +
    `<p class="checks-warning"><strong>${escapeHtml(CHECKS_TEXT)}</strong></p>` +
    (hand ? `<div class="diagram">${handDiagramSvg(task.point_colors)}<ol class="legend" ` +
      `start="0">${legend}</ol></div>` : "") +
    `<h3>Examples</h3><div class="examples">` +
    `${examplesHtml(hand ? handExamples() : objectExamples())}</div>` +
    `<h3>Suggestions</h3><p>${escapeHtml(SUGGESTIONS_TEXT)}</p>` +
    (hand ? `<p>${escapeHtml(MODEL_TEXT)}</p>` : "") +
    "<p class=\"hint\">Press <kbd>?</kbd> for keyboard shortcuts.</p>";
}

/** Keyboard shortcuts, as [keys, what] rows, for the overlay. */
export const SHORTCUTS = [
  ["← / →", "previous / next frame"],
  ["Shift + ← / →", "10 frames back / forward"],
  ["Home / End", "first / last frame"],
  ["[ / ]", "previous / next keyframe of the active point"],
  ["Space", "play / pause (hold and drag to pan)"],
  ["O", "toggle occluded for the active point in this frame"],
  ["N", "next point"],
  ["1-9, 0", "pick joint 1-9, 0 picks joint 10 (object tasks: 1, 2 pick the landmarks)"],
  ["Shift + 1-9, 0", "pick joint 11-19, Shift + 0 picks joint 20"],
  ["W", "pick the wrist (joint 0)"],
  ["C", "copy the previous keyframe's pose onto this frame (every unlocked point)"],
  ["Shift + drag a point", "move the whole skeleton (locked points stay)"],
  ["Alt + drag or Ctrl + drag", "move one finger: the joint and the joints after it to the tip"],
  ["G", "go to a frame (type its number, Enter)"],
  ["H", "hide / show the active point (view only; not saved)"],
  ["T / Shift + T", "track the active point between its keyframes, or onward from its last " +
    "(back from its first) / every point"],
  ["M", "hand tasks: follow the hand with the hand model from a frame where you placed at " +
    "least 6 joints"],
  ["Enter / Esc", "accept the proposals on the frames you have viewed / discard them"],
  ["U / Shift + U", "use the suggestions from other views: active point / every point"],
  ["E", "show / hide the epipolar lines from the labelled views"],
  ["Delete", "remove the active point's keyframe in this frame"],
  ["Ctrl + Z / Ctrl + Shift + Z", "undo / redo"],
  ["F", "fit the image to the window"],
  ["Wheel", "zoom about the cursor"],
  ["Right-drag", "pan"],
  ["?", "show / hide this list"],
];

/** @param {HTMLElement} list  a <dl> */
export function renderShortcuts(list) {
  list.innerHTML = SHORTCUTS.map(([k, what]) =>
    `<dt><kbd>${escapeHtml(k)}</kbd></dt><dd>${escapeHtml(what)}</dd>`).join("");
}
