"""Question documents a HIT may carry, and the answers document a submission produces."""

from __future__ import annotations

import pytest

from backend.market.errors import RequestError
from backend.market.questions import (
    answers_xml,
    external_url,
    parse_answers,
    validate_question,
)
from tests.backend.market.helpers import external_question

HTML_QUESTION = ('<HTMLQuestion xmlns="http://mechanicalturk.amazonaws.com/'
                 'AWSMechanicalTurkDataSchemas/2011-11-11/HTMLQuestion.xsd">'
                 "<HTMLContent><![CDATA[<p>hi</p>]]></HTMLContent><FrameHeight>0</FrameHeight>"
                 "</HTMLQuestion>")


def test_external_and_html_questions_are_accepted() -> None:
    question = external_question("http://127.0.0.1:8000/annotate/?t=abc&v=2".replace("&", "&amp;"))
    assert validate_question(question) == "ExternalQuestion"
    assert external_url(question) == "http://127.0.0.1:8000/annotate/?t=abc&v=2"
    assert validate_question(HTML_QUESTION) == "HTMLQuestion"


@pytest.mark.parametrize(("xml", "fragment"), [
    (external_question(height=-5).replace("-5", "tall"), "FrameHeight"),
    (HTML_QUESTION.replace("<FrameHeight>0</FrameHeight>", ""), "needs a FrameHeight"),
    ("<x>" + "a" * 70000 + "</x>", "larger than 65535 bytes"),
])
def test_malformed_questions_are_refused(xml: str, fragment: str) -> None:
    with pytest.raises(RequestError, match=fragment):
        validate_question(xml)


def test_answers_round_trip_with_markup_and_unicode() -> None:
    fields = [("tracks", '[[0, 1.5, 2, 1]]'), ("comment", "a < b & 'c' — ü")]
    document = answers_xml(fields)
    assert document.startswith('<?xml version="1.0" encoding="UTF-8"?><QuestionFormAnswers')
    assert parse_answers(document) == dict(fields)
