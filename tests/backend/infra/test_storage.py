from __future__ import annotations

import urllib.request
from pathlib import Path

import pytest

from backend.errors import NotFound
from backend.storage import LocalStorage, S3Storage


@pytest.fixture(params=["local", "s3"])
def storage(request: pytest.FixtureRequest, tmp_path: Path):  # type: ignore[no-untyped-def]
    if request.param == "local":
        return LocalStorage(tmp_path / "store")
    endpoint = request.getfixturevalue("s3_endpoint")
    bucket = request.getfixturevalue("s3_bucket")
    return S3Storage(f"s3://{bucket}/dexlabel", endpoint, "us-east-1")


def test_put_then_get_returns_the_same_bytes(storage) -> None:  # type: ignore[no-untyped-def]
    data = bytes(range(256)) * 100
    storage.put_bytes("captures/abc/cam/color_000000.jpg", data, "image/jpeg")
    assert storage.get_bytes("captures/abc/cam/color_000000.jpg") == data
    assert storage.exists("captures/abc/cam/color_000000.jpg")


def test_missing_key_is_not_found(storage) -> None:  # type: ignore[no-untyped-def]
    assert not storage.exists("captures/none/x.jpg")
    with pytest.raises(NotFound, match=r"captures/none/x\.jpg"):
        storage.get_bytes("captures/none/x.jpg")


def test_delete_prefix_removes_only_that_prefix(storage) -> None:  # type: ignore[no-untyped-def]
    for key in ("captures/a/1.jpg", "captures/a/sub/2.jpg", "captures/ab/3.jpg"):
        storage.put_bytes(key, b"x")
    assert storage.delete_prefix("captures/a") == 2
    assert not storage.exists("captures/a/1.jpg")
    assert not storage.exists("captures/a/sub/2.jpg")
    assert storage.exists("captures/ab/3.jpg")


@pytest.mark.parametrize("key", ["", "/abs", "a/../b", "a//b"])
def test_unsafe_keys_are_refused(storage, key: str) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(ValueError, match="invalid storage key"):
        storage.put_bytes(key, b"x")


def test_s3_presigned_url_serves_the_object(s3_endpoint: str, s3_bucket: str) -> None:
    storage = S3Storage(f"s3://{s3_bucket}", s3_endpoint, "us-east-1")
    storage.put_bytes("f/color.jpg", b"jpegbytes", "image/jpeg")
    url = storage.url_for("f/color.jpg")
    assert url is not None and "Signature" in url
    with urllib.request.urlopen(url) as resp:  # a local moto server
        assert resp.read() == b"jpegbytes"


def test_local_storage_has_no_direct_url(tmp_path: Path) -> None:
    assert LocalStorage(tmp_path).url_for("a/b.jpg") is None


def test_a_file_goes_in_and_streams_out_in_chunks(storage, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from backend.storage import CHUNK_BYTES

    data = bytes(range(256)) * (CHUNK_BYTES // 256 * 2 + 3)  # two whole chunks and a part
    path = tmp_path / "archive.zip"
    path.write_bytes(data)
    storage.put_file("exports/export-000001.zip", path, "application/zip")
    size, chunks = storage.open_stream("exports/export-000001.zip")
    parts = list(chunks)
    assert size == len(data) and b"".join(parts) == data and len(parts) >= 3
    assert path.read_bytes() == data  # the source is left as it was
    with pytest.raises(NotFound, match="export-000009"):
        storage.open_stream("exports/export-000009.zip")


def test_a_listing_names_each_object_under_a_folder_with_its_size_and_age(  # type: ignore[no-untyped-def]
        storage) -> None:
    from datetime import UTC, datetime, timedelta

    storage.put_bytes("exports/export-000001.zip", b"12345")
    storage.put_bytes("exports/sub/export-000002.tar", b"1")
    storage.put_bytes("exportsx/other.zip", b"1")
    listed = storage.list_prefix("exports")
    assert [(o.key, o.size) for o in listed] == [("exports/export-000001.zip", 5),
                                                 ("exports/sub/export-000002.tar", 1)]
    now = datetime.now(UTC)
    assert all(now - timedelta(minutes=5) < o.modified <= now + timedelta(minutes=1)
               for o in listed)
    assert storage.list_prefix("nothing") == []


def test_s3_without_presigned_links_gives_no_direct_url(s3_endpoint: str, s3_bucket: str) -> None:
    """DEXLABEL_S3_PRESIGNED_LINKS=false: a private S3 server; the API serves the objects."""
    storage = S3Storage(f"s3://{s3_bucket}", s3_endpoint, "us-east-1", presigned_links=False)
    storage.put_bytes("f/color.jpg", b"jpegbytes", "image/jpeg")
    assert storage.url_for("f/color.jpg") is None
    assert storage.get_bytes("f/color.jpg") == b"jpegbytes"


@pytest.mark.parametrize("database_url", ["sqlite"], indirect=True)
def test_frames_of_a_private_s3_server_are_served_by_the_api(
    app_env: dict, s3_endpoint: str, s3_bucket: str, small_capture: Path,
    monkeypatch: pytest.MonkeyPatch, request: pytest.FixtureRequest,
) -> None:
    from backend.captures.flows import import_path
    from tests.conftest import reset_caches

    monkeypatch.setenv("DEXLABEL_STORAGE_URL", f"s3://{s3_bucket}/captures")
    monkeypatch.setenv("DEXLABEL_S3_ENDPOINT_URL", s3_endpoint)
    monkeypatch.setenv("DEXLABEL_S3_PRESIGNED_LINKS", "false")
    reset_caches()
    client, headers = request.getfixturevalue("client"), request.getfixturevalue("admin_headers")
    sequence_id = import_path(small_capture)[0].sequence_id
    serial = client.get(f"/api/sequences/{sequence_id}", headers=headers).json()["cameras"][0][
        "serial"]
    manifest = client.get(f"/api/sequences/{sequence_id}/views/{serial}/frames",
                          headers=headers).json()
    first = manifest["frames"][0]["url"]
    assert first.startswith(f"/api/sequences/{sequence_id}/views/{serial}/frames/")
    frame = client.get(first, headers=headers)
    assert frame.status_code == 200 and frame.content[:2] == b"\xff\xd8"  # a JPEG
