"""Serving one view's frames: a manifest of URLs and a single-response bundle.

Bundle format (``application/x-dexlabel-frames``), everything little-endian::

    b"DXLF"  uint32 version (1)  uint32 header_length  header (UTF-8 JSON)  payload

The header is ``{"sequence_id", "serial", "width", "height", "frames": [{"index", "offset",
"length"}]}`` with offsets into the payload, which is the frames' JPEG files back to back.
The browser slices the payload into Blobs and decodes them, so a clip loads in one request.
"""

from __future__ import annotations

import hashlib
import json
import struct
import threading
from collections import OrderedDict
from concurrent.futures import ThreadPoolExecutor

from backend.captures.models import Camera, Frame
from backend.storage import Storage

BUNDLE_MAGIC = b"DXLF"
BUNDLE_VERSION = 1
BUNDLE_MEDIA_TYPE = "application/x-dexlabel-frames"
_READ_THREADS = 8
_CACHE_BYTES = 256 * 1024 * 1024


class _BundleCache:
    """Recently built bundles by camera id; frames never change after import."""

    def __init__(self, max_bytes: int) -> None:
        self.max_bytes = max_bytes
        self._items: OrderedDict[tuple[int, str], bytes] = OrderedDict()
        self._lock = threading.Lock()

    def get(self, key: tuple[int, str]) -> bytes | None:
        with self._lock:
            data = self._items.get(key)
            if data is not None:
                self._items.move_to_end(key)
            return data

    def put(self, key: tuple[int, str], data: bytes) -> None:
        with self._lock:
            self._items[key] = data
            while (sum(len(v) for v in self._items.values()) > self.max_bytes
                   and len(self._items) > 1):
                self._items.popitem(last=False)

    def clear(self) -> None:
        with self._lock:
            self._items.clear()


bundle_cache = _BundleCache(_CACHE_BYTES)


def bundle_etag(camera: Camera, fingerprint: str) -> str:
    digest = hashlib.sha256(f"{fingerprint}/{camera.serial}/v{BUNDLE_VERSION}".encode())
    return f'"{digest.hexdigest()[:32]}"'


def build_bundle(storage: Storage, camera: Camera, frames: list[Frame], etag: str) -> bytes:
    """The bundle of ``frames`` (one camera's, in index order), cached by camera and ETag."""
    key = (camera.id, etag)
    cached = bundle_cache.get(key)
    if cached is not None:
        return cached
    # One build per bundle: the requests that miss it meanwhile (a crowd opening its pages
    # at once) wait for that build instead of each reading every frame again, which stalled
    # every other request of the process for seconds.
    with _BUILDS_GUARD:
        build = _builds.setdefault(key, threading.Lock())
    with build:
        cached = bundle_cache.get(key)
        if cached is None:
            cached = _build(storage, camera, frames)
            bundle_cache.put(key, cached)
    with _BUILDS_GUARD:
        _builds.pop(key, None)
    return cached


_BUILDS_GUARD = threading.Lock()
_builds: dict[tuple[int, str], threading.Lock] = {}


def _build(storage: Storage, camera: Camera, frames: list[Frame]) -> bytes:
    with ThreadPoolExecutor(_READ_THREADS) as pool:
        blobs = list(pool.map(lambda f: storage.get_bytes(f.color_key), frames))
    entries, offset = [], 0
    for frame, blob in zip(frames, blobs, strict=True):
        entries.append({"index": frame.index, "offset": offset, "length": len(blob)})
        offset += len(blob)
    header = json.dumps({
        "sequence_id": camera.sequence_id, "serial": camera.serial,
        "width": camera.width, "height": camera.height, "frames": entries,
    }, separators=(",", ":")).encode()
    return b"".join([BUNDLE_MAGIC, struct.pack("<II", BUNDLE_VERSION, len(header)), header,
                     *blobs])


def parse_bundle(data: bytes) -> tuple[dict, list[bytes]]:
    """Split a bundle back into its header and frame files (used by tests and tools)."""
    if data[:4] != BUNDLE_MAGIC:
        raise ValueError("not a dexlabel frame bundle")
    version, header_len = struct.unpack("<II", data[4:12])
    if version != BUNDLE_VERSION:
        raise ValueError(f"unsupported bundle version {version}")
    header = json.loads(data[12:12 + header_len])
    payload = memoryview(data)[12 + header_len:]
    blobs = [bytes(payload[e["offset"]:e["offset"] + e["length"]]) for e in header["frames"]]
    return header, blobs
