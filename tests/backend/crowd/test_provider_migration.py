"""Migration 0021 on a database that already holds MTurk's crowd rows: they become the mturk
provider's, and the cost totals gain the per-provider lines the report reads."""

from __future__ import annotations

from sqlalchemy import create_engine, inspect, text

from backend.migrate import downgrade, upgrade

TABLES = ("crowd_hits", "crowd_submissions", "crowd_payments", "crowd_worker_actions",
          "crowd_deleted_costs", "assignments")
NOW = "2026-12-01 10:00:00"


def _seed(url: str) -> None:
    engine = create_engine(url)
    with engine.begin() as conn:
        conn.execute(text(
            "INSERT INTO crowd_worker_actions (worker_id, kind, target, created_at) "
            f"VALUES ('A1WORKER', 'block', '', '{NOW}')"))
        for worker, amount, fee in (("A1WORKER", 50, 10), ("A2WORKER", 150, 30)):
            conn.execute(text(
                "INSERT INTO crowd_cost_totals (scope, key, kind, state, amount_cents, "
                f"fee_cents, payments) VALUES ('worker', '{worker}', 'approval', 'done', "
                f"{amount}, {fee}, 1)"))
    engine.dispose()


def test_existing_rows_become_mturks_and_the_totals_gain_the_provider_line(
    database_url: str,
) -> None:
    upgrade(database_url, "0020")
    _seed(database_url)
    upgrade(database_url, "0021")
    engine = create_engine(database_url)
    try:
        for table in TABLES:
            columns = {c["name"]: c for c in inspect(engine).get_columns(table)}
            assert "provider" in columns and not columns["provider"]["nullable"], table
        with engine.connect() as conn:
            assert conn.execute(text(
                "SELECT provider FROM crowd_worker_actions")).scalars().all() == ["mturk"]
            line = conn.execute(text(
                "SELECT key, kind, state, amount_cents, fee_cents, payments FROM "
                "crowd_cost_totals WHERE scope = 'provider'")).all()
        assert [tuple(row) for row in line] == [("mturk", "approval", "done", 200, 40, 2)]
    finally:
        engine.dispose()
    downgrade(database_url, "0020")
    engine = create_engine(database_url)
    try:
        assert "provider" not in {c["name"] for c in
                                  inspect(engine).get_columns("crowd_worker_actions")}
    finally:
        engine.dispose()
