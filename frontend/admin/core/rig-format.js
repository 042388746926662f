/**
 * Rig health as table cells: DOM-free, tested with node --test (tests/js/admin_rig.test.mjs).
 * The report is GET /api/sequences/{id}/rig-health's `report` (backend/rig/schemas.py).
 */

/** @param {number|null|undefined} x @param {number} digits */
function fixed(x, digits) {
  return x === null || x === undefined ? "–" : x.toFixed(digits);
}

/**
 * One row of cells per camera: serial, time offset, pose correction, image shift, residual
 * before → after, depth scale and shift, and the verdict ("ok" or the faults in words).
 * @param {any} report
 * @returns {{ serial: string, cells: string[], faulty: boolean }[]}
 */
export function rigRows(report) {
  return report.cameras.map((/** @type {any} */ c) => {
    const late = c.time_offset_frames;
    const shift = c.depth_shift_px ? `(${c.depth_shift_px[0]}, ${c.depth_shift_px[1]}) px` : "–";
    const scale = c.depth_scale_percent === null ? "–"
      : `${c.depth_scale_percent >= 0 ? "+" : ""}${c.depth_scale_percent.toFixed(2)} %`;
    return {
      serial: c.serial,
      faulty: c.faults.length > 0,
      cells: [
        c.serial,
        late === 0 ? "0" : `${late > 0 ? "+" : ""}${late} frame${Math.abs(late) > 1 ? "s" : ""}`,
        `${fixed(c.rotation_deg, 2)}° ${fixed(c.translation_mm, 1)} mm`,
        `${fixed(c.image_shift_px, 1)} px`,
        `${fixed(c.residual_px_before, 2)} → ${fixed(c.residual_px_after, 2)} px`,
        scale,
        shift,
        c.faults.length ? c.faults.join("; ") : "ok",
      ],
    };
  });
}

/**
 * The sentence above the table: which version this is, whether it is in use, what is off.
 * @param {any} status  the whole GET reply
 */
export function rigSummary(status) {
  const report = status.report;
  if (!report) {
    return status.job_status === "queued" || status.job_status === "running"
      ? "Estimating the rig from the accepted labels…"
      : "No rig-health estimate yet.";
  }
  const shape = (report.hands || []).some((/** @type {any} */ h) => h.faults.length)
    ? " The hand's shape is off." : "";
  const off = (report.faulty.length ? `cameras off: ${report.faulty.join(", ")}.`
    : "no camera is off.") + shape;
  const use = status.version_in_use === 0 ? "the imported calibration is in use"
    : `version ${status.version_in_use} is in use`;
  return `Version ${report.version} from ${report.labels} accepted assignments; ${off} ` +
    `(${use}.)`;
}

/**
 * One line per hand: how far the imported hand shape's bones are from the labelled ones, and
 * the verdict. A shape named off is refined in the version (its fitted betas).
 * @param {any} report
 * @returns {{ text: string, faulty: boolean }[]}
 */
export function rigHandLines(report) {
  return (report.hands || []).map((/** @type {any} */ h) => {
    const calib = h.calib_name ? ` (mano_${h.calib_name})` : "";
    const faulty = h.faults.length > 0;
    const figures = `${fixed(h.bone_diff_median_mm, 1)} mm (median of 20 bones, at most ` +
      `${fixed(h.bone_diff_max_mm, 1)} mm) over ${h.frames} frames`;
    const text = faulty
      ? `Hand ${h.index} ${h.side}${calib}: shape off. Its bones differ from the labelled ` +
        `ones by ${figures}; this version uses the shape fitted to the labels.`
      : `Hand ${h.index} ${h.side}${calib}: shape ok. Its bones are within ${figures} of ` +
        "the labelled ones.";
    return { text, faulty };
  });
}
