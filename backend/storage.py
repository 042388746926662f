"""Frame, model and job output storage: a local folder by default, S3 (or MinIO) through boto3.

Keys are '/'-separated relative paths such as ``captures/<uid>/<serial>/color_000000.jpg`` or
``exports/export-000012.zip``. Every host of a deployment reads and writes the same storage, so
whatever one host writes here (an export archive, a solve result) another can serve. Large
objects go in from a file and come out as a stream of chunks, never whole in memory.
boto3 is touched only here; its ClientError becomes our StorageError.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import UTC, datetime
from functools import lru_cache
from pathlib import Path
from typing import Protocol
from urllib.parse import urlparse

from backend.config import Settings, get_settings
from backend.errors import NotFound, StorageError

CHUNK_BYTES = 1024 * 1024


@dataclass(frozen=True)
class StoredObject:
    """One stored object as a listing shows it: its key, size in bytes, and when it was last
    written (UTC)."""

    key: str
    size: int
    modified: datetime


class Storage(Protocol):
    def put_bytes(self, key: str, data: bytes, content_type: str = ...) -> None: ...
    def put_file(self, key: str, path: Path, content_type: str = ...) -> None: ...
    def get_bytes(self, key: str) -> bytes: ...
    def open_stream(self, key: str) -> tuple[int, Iterator[bytes]]: ...
    def exists(self, key: str) -> bool: ...
    def list_prefix(self, prefix: str) -> list[StoredObject]: ...
    def delete_prefix(self, prefix: str) -> int: ...
    def url_for(self, key: str, expires_s: int = ...) -> str | None: ...


def _check_key(key: str) -> str:
    parts = key.split("/")
    if not key or key.startswith("/") or any(p in ("", ".", "..") for p in parts):
        raise ValueError(f"invalid storage key {key!r}")
    return key


class LocalStorage:
    """Files under one root folder; writes are atomic (temp file + rename)."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root).resolve()
        self.root.mkdir(parents=True, exist_ok=True)

    def _path(self, key: str) -> Path:
        return self.root / _check_key(key)

    def put_bytes(self, key: str, data: bytes, content_type: str = "") -> None:
        path = self._path(key)
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".part-")
        try:
            with os.fdopen(fd, "wb") as fh:
                fh.write(data)
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise

    def put_file(self, key: str, path: Path, content_type: str = "") -> None:
        """The file at ``path`` stored under ``key`` (copied, then renamed into place)."""
        target = self._path(key)
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=".part-")
        os.close(fd)
        try:
            shutil.copyfile(path, tmp)
            os.replace(tmp, target)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise

    def get_bytes(self, key: str) -> bytes:
        try:
            return self._path(key).read_bytes()
        except FileNotFoundError:
            raise NotFound(f"storage object {key!r} does not exist") from None

    def open_stream(self, key: str) -> tuple[int, Iterator[bytes]]:
        """The object's size and its bytes in chunks; NotFound now (not while streaming)."""
        try:
            fh = self._path(key).open("rb")
        except FileNotFoundError:
            raise NotFound(f"storage object {key!r} does not exist") from None
        size = os.fstat(fh.fileno()).st_size

        def chunks() -> Iterator[bytes]:
            with fh:
                while chunk := fh.read(CHUNK_BYTES):
                    yield chunk
        return size, chunks()

    def exists(self, key: str) -> bool:
        return self._path(key).is_file()

    def list_prefix(self, prefix: str) -> list[StoredObject]:
        """The objects under the folder ``prefix`` (files written but not yet in place, whose
        names start with a dot, left out)."""
        folder = self._path(prefix.rstrip("/"))
        if not folder.is_dir():
            return []
        found = []
        for path in sorted(folder.rglob("*")):
            if path.is_file() and not path.name.startswith("."):
                stat = path.stat()
                found.append(StoredObject(path.relative_to(self.root).as_posix(), stat.st_size,
                                          datetime.fromtimestamp(stat.st_mtime, UTC)))
        return found

    def delete_prefix(self, prefix: str) -> int:
        path = self._path(prefix.rstrip("/"))
        if path.is_file():
            path.unlink()
            return 1
        if not path.is_dir():
            return 0
        count = sum(1 for p in path.rglob("*") if p.is_file())
        shutil.rmtree(path)
        return count

    def url_for(self, key: str, expires_s: int = 3600) -> str | None:
        """Local files have no direct URL; the API streams them."""
        return None


class S3Storage:
    """Objects under ``s3://bucket/prefix`` through boto3 (AWS, MinIO, or moto's server)."""

    def __init__(self, url: str, endpoint_url: str | None, region: str,
                 presigned_links: bool = True) -> None:
        import boto3
        from botocore.config import Config

        parsed = urlparse(url)
        if parsed.scheme != "s3" or not parsed.netloc:
            raise ValueError(f"STORAGE_URL {url!r} is not of the form s3://bucket/prefix")
        self.bucket = parsed.netloc
        self.prefix = parsed.path.strip("/")
        self.presigned_links = presigned_links
        self.client = boto3.client(
            "s3",
            endpoint_url=endpoint_url,
            region_name=region,
            config=Config(retries={"max_attempts": 5, "mode": "standard"}),
        )

    def _key(self, key: str) -> str:
        key = _check_key(key)
        return f"{self.prefix}/{key}" if self.prefix else key

    def _call(self, what: str, fn, **kwargs):  # type: ignore[no-untyped-def]
        from botocore.exceptions import BotoCoreError, ClientError

        try:
            return fn(**kwargs)
        except ClientError as exc:
            code = exc.response.get("Error", {}).get("Code", "")
            if code in ("NoSuchKey", "404", "NotFound"):
                raise NotFound(f"storage object {kwargs.get('Key')!r} does not exist") from None
            raise StorageError(f"S3 {what} failed: {code or exc}") from exc
        except BotoCoreError as exc:
            raise StorageError(f"S3 {what} failed: {exc}") from exc

    def put_bytes(
        self, key: str, data: bytes, content_type: str = "application/octet-stream"
    ) -> None:
        self._call(
            "put", self.client.put_object,
            Bucket=self.bucket, Key=self._key(key), Body=data, ContentType=content_type,
        )

    def put_file(self, key: str, path: Path,
                 content_type: str = "application/octet-stream") -> None:
        """The file at ``path`` uploaded under ``key`` (in parts when large: boto3's transfer)."""
        from boto3.exceptions import S3UploadFailedError

        try:
            self._call("upload", self.client.upload_file, Filename=str(path),
                       Bucket=self.bucket, Key=self._key(key),
                       ExtraArgs={"ContentType": content_type})
        except S3UploadFailedError as exc:
            raise StorageError(f"S3 upload failed: {exc}") from exc

    def get_bytes(self, key: str) -> bytes:
        resp = self._call("get", self.client.get_object, Bucket=self.bucket, Key=self._key(key))
        return resp["Body"].read()

    def open_stream(self, key: str) -> tuple[int, Iterator[bytes]]:
        """The object's size and its bytes in chunks as S3 sends them."""
        resp = self._call("get", self.client.get_object, Bucket=self.bucket, Key=self._key(key))
        body = resp["Body"]

        def chunks() -> Iterator[bytes]:
            try:
                yield from body.iter_chunks(CHUNK_BYTES)
            finally:
                body.close()
        return int(resp["ContentLength"]), chunks()

    def exists(self, key: str) -> bool:
        try:
            self._call("head", self.client.head_object, Bucket=self.bucket, Key=self._key(key))
        except NotFound:
            return False
        return True

    def list_prefix(self, prefix: str) -> list[StoredObject]:
        """The objects under the folder ``prefix``, keys relative to this storage's prefix."""
        full = self._key(prefix.rstrip("/")) + "/"
        skip = len(self.prefix) + 1 if self.prefix else 0
        paginator = self.client.get_paginator("list_objects_v2")
        found = []
        try:
            for page in paginator.paginate(Bucket=self.bucket, Prefix=full):
                found += [StoredObject(o["Key"][skip:], int(o["Size"]),
                                       o["LastModified"].astimezone(UTC))
                          for o in page.get("Contents", [])]
        except Exception as exc:  # botocore's errors, as _call words them
            raise StorageError(f"S3 list failed: {exc}") from exc
        return found

    def delete_prefix(self, prefix: str) -> int:
        full = self._key(prefix.rstrip("/"))
        paginator = self.client.get_paginator("list_objects_v2")
        deleted = 0
        for page in paginator.paginate(Bucket=self.bucket, Prefix=full):
            keys = [{"Key": o["Key"]} for o in page.get("Contents", [])
                    if o["Key"] == full or o["Key"].startswith(full + "/")]
            for start in range(0, len(keys), 1000):
                chunk = keys[start:start + 1000]
                self._call("delete", self.client.delete_objects,
                           Bucket=self.bucket, Delete={"Objects": chunk, "Quiet": True})
                deleted += len(chunk)
        return deleted

    def url_for(self, key: str, expires_s: int = 3600) -> str | None:
        """A presigned GET URL the browser can fetch directly; None with presigned links off
        (DEXLABEL_S3_PRESIGNED_LINKS=false: the S3 server is not reachable from browsers, the
        API streams the object)."""
        if not self.presigned_links:
            return None
        return self.client.generate_presigned_url(
            "get_object", Params={"Bucket": self.bucket, "Key": self._key(key)},
            ExpiresIn=expires_s,
        )


def make_storage(settings: Settings) -> Storage:
    if settings.storage_url.startswith("s3://"):
        return S3Storage(settings.storage_url, settings.s3_endpoint_url, settings.s3_region,
                         settings.s3_presigned_links)
    if "://" in settings.storage_url and not settings.storage_url.startswith("file://"):
        raise ValueError(f"STORAGE_URL {settings.storage_url!r}: use a folder or s3://bucket/prefix")
    return LocalStorage(settings.storage_url.removeprefix("file://"))


@lru_cache
def get_storage() -> Storage:
    return make_storage(get_settings())
