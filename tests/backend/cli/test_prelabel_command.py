"""`dexlabel prelabel` and backend.captures.prelabel: proposals on a synthetic capture's views
scored against its truth (with a prelabeler of known answers), and the command's refusals
without the optional extra or a capture."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from backend.captures.prelabel import overall, prelabel_capture
from backend.cli import app
from backend.errors import DexlabelError
from worker.assist.prelabel import (
    HandProposal,
    HandSide,
    Prelabeler,
    mediapipe_available,
)
from worker.formats import dexycb
from worker.synth import SynthSummary, generate_capture

FRAMES = 3


@pytest.fixture(scope="module")
def capture(tmp_path_factory: pytest.TempPathFactory) -> SynthSummary:
    return generate_capture(tmp_path_factory.mktemp("prelabel") / "cap", seed=67, frames=FRAMES,
                            views=2, objects=1, width=320, height=240, workers=1)


class ImageCentre:
    """Proposes every joint at the image's centre in the even frames, nothing in the odd ones."""

    name = "image-centre"

    def __init__(self) -> None:
        self.sides: list[str] = []

    def propose(self, images: Sequence[np.ndarray], side: HandSide
                ) -> list[HandProposal | None]:
        self.sides.append(side)
        return [HandProposal(np.tile([(im.shape[1] - 1) / 2, (im.shape[0] - 1) / 2], (21, 1)),
                             np.ones(21), side, 1.0) if f % 2 == 0 else None
                for f, im in enumerate(images)]


def test_proposals_are_scored_against_each_views_own_truth(capture: SynthSummary):
    model = ImageCentre()
    prelabeler: Prelabeler = model
    views = prelabel_capture(capture.root, prelabeler)
    assert [v.serial for v in views] == capture.serials and model.sides == ["right", "right"]
    for v in views:
        folder = capture.root / capture.subject / capture.sequence / v.serial
        want, seen = [], 0
        for f in range(FRAMES):
            with np.load(folder / dexycb.labels_file(f)) as labels:
                visible = (labels[dexycb.SEG] == dexycb.HAND_SEG_VALUE).sum() >= 500
                seen += int(visible)
                if f % 2 == 0 and visible:
                    want.append(np.linalg.norm(labels[dexycb.JOINT_2D][0] - [159.5, 119.5],
                                               axis=1))
        assert v.score.visible == seen and v.score.found == len(want)
        if want:
            assert v.score.median_px() == pytest.approx(float(np.median(np.concatenate(want))),
                                                        abs=1e-3)
    total = overall(views)
    assert total["frames"] == 2 * FRAMES
    assert total["found"] == sum(v.score.found for v in views)
    errors = np.concatenate([v.score.errors_px for v in views]).reshape(-1, 21)
    assert total["median_px_by_joint"]["wrist"] == pytest.approx(np.median(errors[:, 0]),
                                                                  abs=0.01)


def test_an_unknown_view_is_refused_with_the_capture_views(capture: SynthSummary):
    with pytest.raises(DexlabelError, match=capture.serials[0]):
        prelabel_capture(capture.root, ImageCentre(), views=["000000000000"])


@pytest.mark.skipif(mediapipe_available(), reason="the prelabel extra is installed here")
def test_prelabel_without_the_extra_names_it(capture: SynthSummary):
    done = CliRunner().invoke(app, ["prelabel", str(capture.root)])
    assert done.exit_code == 2
    assert "pip install 'dexlabel[prelabel]'" in done.output


def test_prelabel_of_a_missing_folder_is_refused(tmp_path: Path):
    done = CliRunner().invoke(app, ["prelabel", str(tmp_path / "nothing")])
    assert done.exit_code == 2
    assert done.output.splitlines()[-1] == f"error: {tmp_path / 'nothing'} is not a folder"


@pytest.mark.skipif(not mediapipe_available(),
                    reason="needs the optional extra: pip install 'dexlabel[prelabel]'")
def test_prelabel_reports_one_view_as_json(capture: SynthSummary):
    serial = capture.serials[1]
    done = CliRunner().invoke(app, ["prelabel", str(capture.root), "--view", serial, "--json"])
    assert done.exit_code == 0, done.output
    report = json.loads(done.output.splitlines()[-1])
    assert [v["serial"] for v in report["views"]] == [serial]
    assert report["overall"]["frames"] == FRAMES and report["video"] is True
