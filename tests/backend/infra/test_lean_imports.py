"""An API process and the light CLI commands load neither PyTorch nor the solver's numerics.

Every `serve --workers N` process pays what create_app() imports, so the hand model and solver
packages load their PyTorch parts only when a hand is posed or a solve runs. Each check runs in
a fresh interpreter: this test process has long since imported everything.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
# Modules that only posing a hand or solving needs (each imports PyTorch).
HEAVY = ("torch", "worker.hand.layer", "worker.hand.posing", "worker.solver.entry",
         "worker.solver.lm")


def _loaded_after(code: str, tmp_path: Path) -> dict[str, bool]:
    """Which of HEAVY a fresh interpreter holds after running ``code``."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("DEXLABEL_")}
    env.update(DEXLABEL_VAR_DIR=str(tmp_path / "var"), DEXLABEL_ENV="test",
               PYTHONPATH=os.pathsep.join([str(ROOT), *filter(None, [env.get("PYTHONPATH")])]))
    probe = (f"{code}\nimport json, sys\n"
             f"print(json.dumps({{m: m in sys.modules for m in {HEAVY!r}}}))")
    out = subprocess.run([sys.executable, "-c", probe], cwd=ROOT, env=env, capture_output=True,
                         text=True, timeout=300, check=False)
    assert out.returncode == 0, out.stderr[-3000:]
    loaded: dict[str, bool] = json.loads(out.stdout.strip().splitlines()[-1])
    return loaded


def test_create_app_loads_neither_torch_nor_the_solver(tmp_path: Path) -> None:
    loaded = _loaded_after("from backend.app import create_app\ncreate_app()", tmp_path)
    assert loaded == dict.fromkeys(HEAVY, False)


def test_status_and_export_commands_load_no_torch(tmp_path: Path) -> None:
    # What `dexlabel status` and `dexlabel export` import before they read the database.
    code = ("import backend.cli\nimport backend.cli.status\nimport backend.progress.service\n"
            "import backend.exports.service")
    assert _loaded_after(code, tmp_path) == dict.fromkeys(HEAVY, False)


def test_package_faces_still_give_every_name(tmp_path: Path) -> None:
    # The lazy names load on first use and are the defining modules' own objects.
    import worker.hand
    import worker.solver
    from worker.hand.layer import HandLayer
    from worker.solver.entry import solve

    assert worker.hand.HandLayer is HandLayer and worker.solver.solve is solve
    for package in (worker.hand, worker.solver):
        assert all(getattr(package, name) is not None for name in package.__all__)
    assert _loaded_after("import worker.hand\nimport worker.solver", tmp_path) == dict.fromkeys(
        HEAVY, False)
