"""A reward on MTurk is at least $0.01 wherever it is given: the command line, the API (the
mturk provider's check before publishing; the schema takes 0, which a team unit may pay) and
the built-in marketplace's CreateHIT each refuse $0.00 with a clear error, and publish
nothing."""

from __future__ import annotations

from typing import Any

import pytest
from typer.testing import CliRunner

from tests.backend.market.helpers import hit_params


def test_the_cli_refuses_a_reward_under_one_cent(crowd_url: str, tasks: list[int]) -> None:
    from backend.cli import app

    for reward in ("0", "0.00"):
        out = CliRunner().invoke(app, ["publish", "--dry-run", "--reward", reward])
        assert out.exit_code == 2, out.output
        assert out.output.splitlines()[-1].startswith("error: reward: ")
        assert "0.01" in out.output


def test_the_api_refuses_a_reward_under_one_cent(api: Any, tasks: list[int]) -> None:
    resp = api.post("/api/crowd/publish", json={"reward": "0.00", "min_approval_rate": None})
    assert resp.status_code == 422, resp.text
    body = resp.json()
    assert body["error"] == "provider_refused" and body["fields"][0]["field"] == "reward"
    assert "0.01" in body["fields"][0]["message"]
    assert api.get("/api/crowd/units").json() == []  # nothing published
    one_cent = api.post("/api/crowd/publish",
                        json={"reward": "0.01", "min_approval_rate": None, "dry_run": True})
    assert one_cent.status_code == 200, one_cent.text


def test_the_marketplace_refuses_a_hit_that_pays_nothing(mturk: Any) -> None:
    with pytest.raises(mturk.exceptions.RequestError) as refused:
        mturk.create_hit(**hit_params(Reward="0.00"))
    assert "Reward 0.00 is less than the smallest reward, 0.01" in str(refused.value)
    assert mturk.list_hits()["NumResults"] == 0
    assert mturk.create_hit(**hit_params(Reward="0.01"))["HIT"]["Reward"] == "0.01"
