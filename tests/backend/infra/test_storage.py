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
