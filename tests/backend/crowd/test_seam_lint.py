"""The crowd seam's lint (tests/lint_crowd_seam.py): MTurk operations are named only in the
providers, and a call by name, by attribute or in CamelCase is caught elsewhere."""

from __future__ import annotations

from pathlib import Path

from tests import lint_crowd_seam as seam

SNIPPET = '''
from backend.crowd import decisions

def pay(client, intent):
    call(client, "create_hit", Title="t")
    client.send_bonus(WorkerId="A1")
    decisions.send_bonus(None, intent)  # our own module's function: not MTurk
    return "ListAssignmentsForHIT"
'''


def test_backend_names_no_mturk_operation_outside_the_providers() -> None:
    assert seam.main([]) == 0


def test_a_call_by_name_by_attribute_and_in_camelcase_is_found(tmp_path: Path) -> None:
    source = tmp_path / "domain.py"
    source.write_text(SNIPPET)
    camel, snake = seam.operations()
    found = list(seam.findings(source, camel, snake))
    named = sorted(line.split("operation ")[1].split(";")[0] for line in found)
    assert named == ["'ListAssignmentsForHIT'", "'create_hit'", "'send_bonus'"]
    assert all(":5:" in line or ":6:" in line or ":8:" in line for line in found)


def test_the_providers_and_the_marketplace_may_speak_mturk() -> None:
    listed = {p.relative_to(seam.ROOT).as_posix() for p in seam.sources(["backend/crowd"])}
    assert "backend/crowd/decisions.py" in listed
    assert not any(p.startswith("backend/crowd/providers/") for p in listed)
