"""A QC rejection's feedback fits the marketplace's limit: whole sentences first, the cut said."""

from __future__ import annotations

import re

from backend.crowd.decisions import fit_feedback
from backend.market.assignments import MAX_FEEDBACK


def test_long_feedback_is_cut_at_a_sentence_and_fits_the_marketplace() -> None:
    sentences = [f"Joint {i} of your track is 12.5 px off the other views in frames 3-9. "
                 f"Check it on each frame (view {i % 4})." for i in range(40)]
    text = " ".join(sentences)
    assert len(text) > MAX_FEEDBACK
    fitted = fit_feedback(text)
    assert len(fitted) <= MAX_FEEDBACK
    assert re.search(r"(\(view \d\)|frames 3-9)\. \.\.\.$", fitted), fitted[-40:]
    assert text.startswith(fitted[: -len(" ...")])
    assert fit_feedback("Short and clear.") == "Short and clear."


def test_one_overlong_sentence_is_cut_at_a_word() -> None:
    text = "word " * 400
    fitted = fit_feedback(text.strip())
    assert len(fitted) <= MAX_FEEDBACK and fitted.endswith("word ...")
