"""Settings are checked when they load: DEXLABEL_QC_THRESHOLDS names only fields of the QC
decision's settings with numbers of the right type, and a refused setting stops a command with
a line naming it. The README's Settings table documents every field with its default."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from pydantic import ValidationError

from backend.config import InvalidSettings, Settings, get_settings
from worker.quality.decide import QCThresholds

README = Path(__file__).resolve().parents[3] / "README.md"
QC_KEYS = "k_reject, k_review, landmark_min_separation_mm, min_population, motion_ratio_high"


@pytest.fixture
def clean_env(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> pytest.MonkeyPatch:
    """No DEXLABEL_ variable and no .env file: the settings' own defaults."""
    for name in list(os.environ):
        if name.startswith("DEXLABEL_"):
            monkeypatch.delenv(name)
    monkeypatch.chdir(tmp_path)
    get_settings.cache_clear()
    yield monkeypatch
    get_settings.cache_clear()


class TestQcThresholds:
    def test_known_keys_load_with_their_types_and_build_the_decision_settings(
            self, clean_env: pytest.MonkeyPatch) -> None:
        clean_env.setenv("DEXLABEL_QC_THRESHOLDS",
                         '{"k_review": 2, "min_population": 4.0, "motion_ratio_high": 2.5}')
        loaded = Settings().qc_thresholds
        assert loaded == {"k_review": 2.0, "min_population": 4, "motion_ratio_high": 2.5}
        assert type(loaded["k_review"]) is float and type(loaded["min_population"]) is int
        bounds = QCThresholds(**loaded)
        assert (bounds.k_review, bounds.k_reject, bounds.min_population) == (2.0, 6.0, 4)

    def test_the_landmarks_minimum_separation_is_a_setting(
            self, clean_env: pytest.MonkeyPatch) -> None:
        clean_env.setenv("DEXLABEL_QC_THRESHOLDS", '{"landmark_min_separation_mm": 25}')
        bounds = QCThresholds(**Settings().qc_thresholds)
        assert bounds.landmark_min_separation_mm == 25.0

    @pytest.mark.parametrize("key", ["approve_px_max", "bounds", "K_REVIEW"])
    def test_unknown_key_is_refused_naming_it_and_the_known_ones(
            self, clean_env: pytest.MonkeyPatch, key: str) -> None:
        clean_env.setenv("DEXLABEL_QC_THRESHOLDS", f'{{"k_review": 2.5, "{key}": 8.0}}')
        with pytest.raises(ValidationError) as caught:
            Settings()
        message = str(caught.value)
        assert f"{key!r} is not a QC threshold setting; one of {QC_KEYS}" in message

    @pytest.mark.parametrize(("value", "why"), [
        ('"high"', "k_review must be a number, got 'high'"),
        ("true", "k_review must be a number, got True"),
        ("null", "k_review must be a number, got None"),
        ("[3]", "k_review must be a number, got [3]"),
        ("NaN", "k_review must be a number, got nan"),
        ("0", "k_review must be above 0, got 0"),
        ("-1.5", "k_review must be above 0, got -1.5"),
    ])
    def test_value_of_the_wrong_type_or_range_is_refused(
            self, clean_env: pytest.MonkeyPatch, value: str, why: str) -> None:
        clean_env.setenv("DEXLABEL_QC_THRESHOLDS", f'{{"k_review": {value}}}')
        with pytest.raises(ValidationError, match=re.escape(why)):
            Settings()

    def test_min_population_must_be_whole(self, clean_env: pytest.MonkeyPatch) -> None:
        clean_env.setenv("DEXLABEL_QC_THRESHOLDS", '{"min_population": 2.5}')
        with pytest.raises(ValidationError,
                           match=re.escape("min_population must be a whole number, got 2.5")):
            Settings()


class TestGetSettings:
    def test_refusal_names_each_variable_on_its_own_line(
            self, clean_env: pytest.MonkeyPatch) -> None:
        clean_env.setenv("DEXLABEL_QC_THRESHOLDS", '{"approve_px_max": 8.0}')
        clean_env.setenv("DEXLABEL_WORKER_THREADS", "0")
        with pytest.raises(InvalidSettings) as caught:
            get_settings()
        lines = caught.value.detail.splitlines()
        unknown = ("DEXLABEL_QC_THRESHOLDS: 'approve_px_max' is not a QC threshold setting; "
                   f"one of {QC_KEYS}")
        assert lines == ["DEXLABEL_WORKER_THREADS: Input should be greater than or equal to 1",
                         unknown]

    def test_json_that_does_not_parse_is_named(self, clean_env: pytest.MonkeyPatch) -> None:
        clean_env.setenv("DEXLABEL_QC_THRESHOLDS", "{k_review: 2}")
        with pytest.raises(InvalidSettings, match=r"^DEXLABEL_QC_THRESHOLDS is not valid JSON"):
            get_settings()

    def test_a_command_stops_with_the_refusal_and_no_traceback(
            self, clean_env: pytest.MonkeyPatch, tmp_path: Path) -> None:
        env = {**os.environ, "DEXLABEL_VAR_DIR": str(tmp_path / "var"),
               "DEXLABEL_QC_THRESHOLDS": '{"approve_px_max": 8.0}'}
        done = subprocess.run([sys.executable, "-m", "backend.cli", "jobs", "list"], env=env,
                              capture_output=True, text=True, timeout=120, check=False)
        assert done.returncode == 2, done.stderr
        assert done.stderr.strip() == (
            f"error: DEXLABEL_QC_THRESHOLDS: 'approve_px_max' is not a QC threshold setting; "
            f"one of {QC_KEYS}")
        assert not (tmp_path / "var").exists()


def _readme_settings() -> dict[str, tuple[str, str]]:
    """DEXLABEL_ name -> (default cell, meaning cell) of the README's Settings table."""
    text = README.read_text()
    section = text[text.index("## Settings\n"):]
    section = section[:section.index("\n## ", 1)]
    rows: dict[str, tuple[str, str]] = {}
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) != 3 or not cells[0].startswith("`DEXLABEL_"):
            continue
        for name in re.findall(r"`(DEXLABEL_[A-Z0-9_]+)`", cells[0]):
            rows[name] = (cells[1], cells[2])
    return rows


def _shown(value: object) -> str:
    """A default as the README writes it."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, dict):
        return "{}" if not value else repr(value)
    return str(value)


class TestReadmeSettings:
    def test_every_setting_is_documented_and_nothing_else(self) -> None:
        documented = set(_readme_settings())
        fields = {f"DEXLABEL_{name.upper()}" for name in Settings.model_fields}
        assert documented == fields

    def test_documented_defaults_are_the_code_defaults(
            self, clean_env: pytest.MonkeyPatch) -> None:
        settings = Settings()
        rows = _readme_settings()
        checked = 0
        for name in Settings.model_fields:
            cell, meaning = rows[f"DEXLABEL_{name.upper()}"]
            value = getattr(settings, name)
            assert meaning, name
            if cell == "unset":
                assert value is None, f"{name} is documented unset but defaults to {value!r}"
                checked += 1
            elif re.fullmatch(r"`[^`]*`", cell):
                shown = cell.strip("`").replace("{VAR_DIR}", _shown(settings.var_dir))
                assert shown == _shown(value), f"{name}: README {shown!r}, code {value!r}"
                checked += 1
        # Only the secrets and key pairs are described in words rather than shown.
        assert checked == len(Settings.model_fields) - 4
