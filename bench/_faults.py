"""What the benchmarks share about rig faults (worker/synth/faults.py): the faults a `--fault`
option names, and each one's faulty copy of a capture, made once and kept in the run's folder.
"""

from __future__ import annotations

from pathlib import Path

from worker.synth.faults import inject_faults, parse_fault, split_fault_names

CLEAN = "none"
HELP = ("rig fault(s) to run under, repeatable or a comma list (none, extrinsics:DEG,MM, "
        "late:N, depth-scale:S, depth-shift:LO-HI, betas); each is reported on its own")


def fault_names(values: list[str] | None) -> list[str]:
    """The faults to run, in order, validated (``[CLEAN]`` when none is asked for); ValueError
    naming a bad one."""
    names = split_fault_names(values or []) or [CLEAN]
    for name in names:
        if name != CLEAN:
            parse_fault(name)
    return list(dict.fromkeys(names))


def faulty_capture(capture: Path, fault: str, work: Path, seed: int = 0) -> Path:
    """The copy of ``capture`` with ``fault`` injected (``capture`` itself for CLEAN), under
    ``work``, written on first use."""
    if fault == CLEAN:
        return capture
    slug = fault.replace(":", "-").replace(",", "_")
    out = Path(work) / f"{Path(capture).name}__{slug}_f{seed}"
    if not out.is_dir():
        inject_faults(capture, out, [parse_fault(fault)], seed=seed)
    return out
