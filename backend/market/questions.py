"""Question and answer XML: what a HIT asks (ExternalQuestion, HTMLQuestion, QuestionForm)
and what a worker returns (QuestionFormAnswers, 2005-10-01)."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from urllib.parse import urlsplit

from backend.market.errors import XML_PARSE_ERROR, RequestError, invalid

_SCHEMAS = "http://mechanicalturk.amazonaws.com/AWSMechanicalTurkDataSchemas"
EXTERNAL_QUESTION_NS = f"{_SCHEMAS}/2006-07-14/ExternalQuestion.xsd"
HTML_QUESTION_NS = f"{_SCHEMAS}/2011-11-11/HTMLQuestion.xsd"
QUESTION_FORM_NS = (f"{_SCHEMAS}/2005-10-01/QuestionForm.xsd",
                    f"{_SCHEMAS}/2017-11-06/QuestionForm.xsd")
ANSWERS_NS = f"{_SCHEMAS}/2005-10-01/QuestionFormAnswers.xsd"
MAX_QUESTION_BYTES = 65535  # MTurk's documented limit on the Question parameter
MAX_FRAME_HEIGHT = 10000


def _parse(xml: str, member: str) -> ET.Element:
    if len(xml.encode()) > MAX_QUESTION_BYTES:
        raise invalid(f"{member} is larger than {MAX_QUESTION_BYTES} bytes")
    try:
        return ET.fromstring(xml)
    except ET.ParseError as exc:
        raise RequestError(f"{member} is not well-formed XML: {exc}", XML_PARSE_ERROR) from exc


def _child_text(root: ET.Element, ns: str, name: str, member: str) -> str:
    node = root.find(f"{{{ns}}}{name}")
    if node is None or not (node.text or "").strip():
        raise invalid(f"{member}: {root.tag.split('}')[-1]} needs a {name} element")
    return (node.text or "").strip()


def _frame_height(root: ET.Element, ns: str, member: str) -> None:
    text = _child_text(root, ns, "FrameHeight", member)
    if not text.isdigit() or int(text) > MAX_FRAME_HEIGHT:
        raise invalid(f"{member}: FrameHeight must be 0 to {MAX_FRAME_HEIGHT} pixels, got {text}")


def validate_question(xml: str, member: str = "Question") -> str:
    """Accept only the three question documents MTurk accepts, with their required parts;
    answer which of them ``xml`` is."""
    root = _parse(xml, member)
    ns, _, name = root.tag[1:].partition("}") if root.tag.startswith("{") else ("", "", root.tag)
    if name == "ExternalQuestion" and ns == EXTERNAL_QUESTION_NS:
        url = _child_text(root, ns, "ExternalURL", member)
        parts = urlsplit(url)
        if parts.scheme not in ("http", "https") or not parts.netloc:
            raise invalid(f"{member}: ExternalURL {url!r} is not an http(s) URL")
        _frame_height(root, ns, member)
    elif name == "HTMLQuestion" and ns == HTML_QUESTION_NS:
        _child_text(root, ns, "HTMLContent", member)
        _frame_height(root, ns, member)
    elif name == "QuestionForm" and ns in QUESTION_FORM_NS:
        if root.find(f"{{{ns}}}Question") is None:
            raise invalid(f"{member}: a QuestionForm needs at least one Question")
    else:
        raise invalid(f"{member} must be an ExternalQuestion, HTMLQuestion or QuestionForm "
                      f"document in its MTurk namespace, got {root.tag}")
    return name


def external_url(xml: str) -> str | None:
    """The ExternalURL of an ExternalQuestion (None for other question kinds)."""
    root = ET.fromstring(xml)
    node = root.find(f"{{{EXTERNAL_QUESTION_NS}}}ExternalURL")
    return None if node is None else (node.text or "").strip()


def answers_xml(fields: list[tuple[str, str]]) -> str:
    """A QuestionFormAnswers document with one free-text Answer per (name, value)."""
    root = ET.Element("QuestionFormAnswers", xmlns=ANSWERS_NS)
    for name, value in fields:
        answer = ET.SubElement(root, "Answer")
        ET.SubElement(answer, "QuestionIdentifier").text = name
        ET.SubElement(answer, "FreeText").text = value
    return '<?xml version="1.0" encoding="UTF-8"?>' + ET.tostring(root, encoding="unicode")


def parse_answers(xml: str) -> dict[str, str]:
    """QuestionIdentifier -> FreeText of a QuestionFormAnswers document."""
    root = ET.fromstring(xml)
    ns = {"a": ANSWERS_NS}
    return {a.findtext("a:QuestionIdentifier", "", ns): a.findtext("a:FreeText", "", ns)
            for a in root.findall("a:Answer", ns)}
