from __future__ import annotations

from sqlalchemy import create_engine, inspect

from backend.migrate import current_heads, downgrade, upgrade

EXPECTED_TABLES = {"subjects", "sequences", "cameras", "scene_objects", "hands", "frames", "admins"}


def _tables(url: str) -> set[str]:
    engine = create_engine(url)
    try:
        return set(inspect(engine).get_table_names()) - {"alembic_version"}
    finally:
        engine.dispose()


def test_migrations_run_forward_back_to_base_and_forward_again(database_url: str) -> None:
    upgrade(database_url)
    assert _tables(database_url) >= EXPECTED_TABLES
    downgrade(database_url, "base")
    assert _tables(database_url) == set()
    upgrade(database_url)
    assert _tables(database_url) >= EXPECTED_TABLES


def test_migrated_schema_matches_the_models(database_url: str) -> None:
    """Autogenerate finds nothing to do: the ORM models and the migrations agree."""
    from alembic.autogenerate import compare_metadata
    from alembic.migration import MigrationContext

    import backend.models  # noqa: F401
    from backend.db import Base

    upgrade(database_url)
    engine = create_engine(database_url)
    try:
        with engine.connect() as conn:
            diff = compare_metadata(MigrationContext.configure(conn), Base.metadata)
    finally:
        engine.dispose()
    assert diff == []


def test_there_is_one_head() -> None:
    assert len(current_heads()) == 1
