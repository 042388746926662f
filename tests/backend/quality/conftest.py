"""QC tests run the product end to end: the app and its marketplace served by uvicorn, simulated
workers over HTTP, the QC job, boto3 reading the marketplace's record."""

from __future__ import annotations

from tests.crowd.conftest import crowd_url, market_env
from tests.market.conftest import market_database_url, market_url, migrated_sqlite

__all__ = ["crowd_url", "market_database_url", "market_env", "market_url", "migrated_sqlite"]


import pytest


@pytest.fixture(scope="session")
def qc_capture(tmp_path_factory: pytest.TempPathFactory):
    """A synthetic capture with enough views and frames for a consensus (6 views x 16 frames,
    320x240 to keep it quick)."""
    from worker.synth import generate_capture

    root = tmp_path_factory.mktemp("qc-capture")
    generate_capture(root, seed=5, frames=16, views=6, objects=1, width=320, height=240)
    return root


@pytest.fixture(scope="session")
def training_capture(tmp_path_factory: pytest.TempPathFactory):
    """A clip as long as the real ones relative to its size (2 views x 48 frames, 320x240): a
    careful worker's keyframe interpolation stays within a few pixels of the gold."""
    from worker.synth import generate_capture

    root = tmp_path_factory.mktemp("training-capture")
    generate_capture(root, seed=6, frames=48, views=2, objects=1, width=320, height=240)
    return root
