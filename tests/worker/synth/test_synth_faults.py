"""worker.synth.faults: each rig fault is applied as stated, and the truth stays the source's."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from backend.captures.layout import read_sequence
from worker.formats import dexycb
from worker.synth import SynthSummary, generate_capture
from worker.synth.faults import (
    Fault,
    inject_faults,
    parse_fault,
    parse_faults,
    read_record,
    shift_image,
    shown_frames,
    true_extrinsics,
)

SMALL = {"seed": 9, "frames": 4, "views": 3, "objects": 1, "width": 64, "height": 48}


@pytest.fixture(scope="module")
def source(tmp_path_factory: pytest.TempPathFactory) -> SynthSummary:
    return generate_capture(tmp_path_factory.mktemp("src") / "cap", workers=1, **SMALL)


def _seq(root: Path, summary: SynthSummary) -> Path:
    return root / summary.subject / summary.sequence


def _depth(root: Path, summary: SynthSummary, serial: str, frame: int) -> np.ndarray:
    path = _seq(root, summary) / serial / dexycb.depth_file(frame)
    return cv2.imread(str(path), cv2.IMREAD_ANYDEPTH)


def _truth_files(root: Path) -> dict[str, bytes]:
    return {p.relative_to(root).as_posix(): p.read_bytes()
            for p in sorted(root.rglob("*")) if p.name.startswith("labels_")
            or p.name == dexycb.POSE_FILE}


def _extrinsics(root: Path) -> dict[str, np.ndarray]:
    plan = read_sequence(next(p.parent for p in root.glob(dexycb.META_GLOB)))
    return {c.serial: np.asarray(c.extrinsics, np.float64) for c in plan.cameras}


class TestParse:
    def test_comma_lists_keep_numbers_with_their_fault(self) -> None:
        faults = parse_faults(["extrinsics:0.2,2,late:1", "depth-shift:2-3", "none", "betas"])
        assert [f.name for f in faults] == ["extrinsics:0.2,2", "late:1", "depth-shift:2-3",
                                            "betas"]
        assert faults[0] == Fault("extrinsics", (0.2, 2.0))

    @pytest.mark.parametrize("bad", ["wobble:1", "extrinsics:0.5", "late:0", "late:1.5",
                                     "depth-scale:x", "depth-shift:3-2", "betas:-1"])
    def test_bad_fault_names_the_problem(self, bad: str) -> None:
        with pytest.raises(ValueError, match=r"fault|unknown"):
            parse_fault(bad)


class TestInject:
    def test_truth_is_unchanged_and_importer_reads_the_copy(self, source: SynthSummary,
                                                             tmp_path: Path) -> None:
        out = tmp_path / "f"
        inject_faults(source.root, out, parse_faults(["extrinsics:0.5,5,late:2,betas"]), seed=1)
        assert _truth_files(out) == _truth_files(source.root)
        assert len(_truth_files(out)) == 1 + SMALL["views"] * SMALL["frames"]
        assert read_sequence(_seq(out, source)).num_frames == SMALL["frames"]

    def test_extrinsics_turned_and_moved_by_the_stated_amounts(self, source: SynthSummary,
                                                               tmp_path: Path) -> None:
        out = tmp_path / "f"
        inject_faults(source.root, out, [Fault("extrinsics", (0.5, 5.0))], seed=2)
        before, after = _extrinsics(source.root), _extrinsics(out)
        master = source.serials[0]
        np.testing.assert_array_equal(after[master], before[master])
        for serial in source.serials[1:]:
            turn = after[serial][:, :3] @ before[serial][:, :3].T
            angle = np.degrees(np.arccos(np.clip((np.trace(turn) - 1) / 2, -1, 1)))
            assert angle == pytest.approx(0.5, abs=1e-6)
            moved = np.linalg.norm(after[serial][:, 3] - before[serial][:, 3]) * 1000.0
            assert moved == pytest.approx(5.0, abs=1e-6)
        truth = true_extrinsics(out)
        assert truth is not None
        for serial in source.serials:
            np.testing.assert_allclose(truth[serial], before[serial], atol=1e-12)

    def test_same_seed_same_copy_other_seed_other_copy(self, source: SynthSummary,
                                                       tmp_path: Path) -> None:
        fault = [Fault("extrinsics", (0.2, 2.0))]
        inject_faults(source.root, tmp_path / "a", fault, seed=3)
        inject_faults(source.root, tmp_path / "b", fault, seed=3)
        inject_faults(source.root, tmp_path / "c", fault, seed=4)
        a, b, c = (_extrinsics(tmp_path / n) for n in "abc")
        serial = source.serials[1]
        np.testing.assert_array_equal(a[serial], b[serial])
        assert not np.allclose(a[serial], c[serial])

    @pytest.mark.parametrize("count", [1, 2])
    def test_late_cameras_show_the_previous_frame(self, source: SynthSummary, tmp_path: Path,
                                                  count: int) -> None:
        out = tmp_path / "f"
        record = inject_faults(source.root, out, [Fault("late", (float(count),))], seed=5)
        late = sorted(s for s, c in record["cameras"].items() if c.get("lag_frames"))
        assert len(late) == count and source.serials[0] not in late
        for serial in source.serials:
            lag = 1 if serial in late else 0
            np.testing.assert_array_equal(shown_frames(out, serial, 4), np.maximum(
                np.arange(4) - lag, 0))
            for f in range(SMALL["frames"]):
                src_dir, dst_dir = _seq(source.root, source) / serial, _seq(out, source) / serial
                shown = max(f - lag, 0)
                for name in (dexycb.color_file, dexycb.depth_file):
                    assert (dst_dir / name(f)).read_bytes() == (src_dir / name(shown)).read_bytes()

    def test_depth_scale_reads_one_percent_far(self, source: SynthSummary,
                                               tmp_path: Path) -> None:
        out = tmp_path / "f"
        inject_faults(source.root, out, [Fault("depth-scale", (0.01,))])
        for serial in source.serials:
            before = _depth(source.root, source, serial, 2).astype(np.float64)
            after = _depth(out, source, serial, 2).astype(np.float64)
            assert ((after == 0) == (before == 0)).all() and (before > 0).any()
            np.testing.assert_allclose(after[before > 0], before[before > 0] * 1.01, atol=0.5)

    def test_depth_shift_moves_depth_against_colour(self, source: SynthSummary,
                                                    tmp_path: Path) -> None:
        out = tmp_path / "f"
        record = inject_faults(source.root, out, [Fault("depth-shift", (2.0, 3.0))], seed=6)
        for serial in source.serials:
            dx, dy = record["cameras"][serial]["depth_shift_px"]
            assert 2.0 <= np.hypot(dx, dy) <= 3.0
            before, after = (_depth(r, source, serial, 1) for r in (source.root, out))
            np.testing.assert_array_equal(after, shift_image(before, dx, dy))
            assert not np.array_equal(after, before)
            colour = dexycb.color_file(1)
            assert (_seq(out, source) / serial / colour).read_bytes() == \
                (_seq(source.root, source) / serial / colour).read_bytes()

    def test_betas_replaced_in_the_calibration_only(self, source: SynthSummary,
                                                    tmp_path: Path) -> None:
        out = tmp_path / "f"
        record = inject_faults(source.root, out, [Fault("betas")], seed=7)
        plan_before = read_sequence(_seq(source.root, source))
        plan_after = read_sequence(_seq(out, source))
        true, wrong = np.array(plan_before.hands[0].betas), np.array(plan_after.hands[0].betas)
        assert np.linalg.norm(wrong - true) > 0.5
        np.testing.assert_allclose(next(iter(record["true_betas"].values())), true)
        assert _truth_files(out) == _truth_files(source.root)

    def test_source_untouched_by_the_copy(self, source: SynthSummary, tmp_path: Path) -> None:
        serial = source.serials[1]
        depth = _depth(source.root, source, serial, 1).copy()
        extr = _extrinsics(source.root)
        inject_faults(source.root, tmp_path / "f",
                      parse_faults(["depth-scale:0.2", "late:1", "extrinsics:3,30"]))
        np.testing.assert_array_equal(_depth(source.root, source, serial, 1), depth)
        assert all(np.array_equal(extr[s], v) for s, v in _extrinsics(source.root).items())
        assert read_record(source.root) is None

    def test_bad_targets_refused(self, source: SynthSummary, tmp_path: Path) -> None:
        with pytest.raises(ValueError, match="only 2 cameras"):
            inject_faults(source.root, tmp_path / "x", [Fault("late", (3.0,))])
        assert not (tmp_path / "x").exists() and not (tmp_path / "x.partial").exists()
        (tmp_path / "full").mkdir()
        (tmp_path / "full" / "a").write_text("")
        with pytest.raises(FileExistsError):
            inject_faults(source.root, tmp_path / "full", [])
        inject_faults(source.root, tmp_path / "y", [])
        with pytest.raises(ValueError, match="already has faults"):
            inject_faults(tmp_path / "y", tmp_path / "z", [])
        assert yaml.safe_load((tmp_path / "y" / "fault.yml").read_text())["faults"] == []
