"""Light commands stay light: `dexlabel status` and a mistyped `dexlabel export` answer without
loading PyTorch or the export's modules, each run as `dexlabel` runs, in a fresh process."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

from tests.backend.cli.conftest import DEXLABEL, clean_env

# Printed by the probe at exit: which of these modules the command loaded.
WATCHED = ("torch", "worker.hand.layer", "worker.solver.entry", "backend.exports.service")
_MARK = "loaded-modules: "


def _run(instance: Path, *args: str) -> tuple[subprocess.CompletedProcess[str], dict[str, bool]]:
    """`dexlabel ARGS` in a fresh process on ``instance``; its result and WATCHED's loads."""
    probe = ("import atexit, json, runpy, sys\n"
             f"atexit.register(lambda: print({_MARK!r} + json.dumps("
             f"{{m: m in sys.modules for m in {WATCHED!r}}}), file=sys.stderr))\n"
             f"sys.argv = ['dexlabel', *{list(args)!r}]\n"
             "runpy.run_module('backend.cli', run_name='__main__')\n")
    done = subprocess.run([DEXLABEL[0], "-c", probe], capture_output=True, text=True,
                          timeout=300, check=False,
                          env=clean_env(DEXLABEL_VAR_DIR=str(instance), DEXLABEL_ENV="test"))
    marked = [line for line in done.stderr.splitlines() if line.startswith(_MARK)]
    assert marked, done.stderr[-3000:]
    return done, json.loads(marked[-1][len(_MARK):])


def test_export_refuses_an_unknown_format_before_it_loads_the_export(
    instance: Path, tmp_path: Path,
) -> None:
    done, loaded = _run(instance, "export", "1", "--format", "nonsense",
                        "--out", str(tmp_path / "labels.zip"))
    assert done.returncode == 2, done.stderr
    assert done.stderr.splitlines()[0] == (
        "error: --format must be one of dexycb, coco, bop, cvat, json; 'nonsense' is none "
        "of them")
    assert loaded == dict.fromkeys(WATCHED, False)
    assert not (tmp_path / "labels.zip").exists()


def test_status_answers_without_loading_torch(instance: Path) -> None:
    done, loaded = _run(instance, "status")
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("no sequences yet"), done.stdout
    assert not loaded["torch"] and not loaded["worker.solver.entry"], loaded
