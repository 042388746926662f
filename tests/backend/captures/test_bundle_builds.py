"""A crowd opening the same view at once gets one bundle build, not one per page.

Before, every request that missed the bundle cache read all of the view's frames again: 100
pages opened together read each frame up to 100 times and stalled every other request of the
server process for seconds (bench/load.py's bursts)."""

from __future__ import annotations

import threading
import time
from collections import Counter
from pathlib import Path

from backend.captures.frames import build_bundle, bundle_cache, bundle_etag, parse_bundle
from backend.captures.models import Camera, Frame
from backend.storage import LocalStorage


class _CountingStorage(LocalStorage):
    """Local files whose reads are counted and take a little time (a busy disk)."""

    def __init__(self, root: Path) -> None:
        super().__init__(root)
        self.reads: Counter[str] = Counter()
        self._lock = threading.Lock()

    def get_bytes(self, key: str) -> bytes:
        with self._lock:
            self.reads[key] += 1
        time.sleep(0.002)
        return super().get_bytes(key)


def test_concurrent_misses_build_the_bundle_once(tmp_path: Path) -> None:
    storage = _CountingStorage(tmp_path)
    frames = []
    for index in range(12):
        key = f"seq/cam/{index:06d}.jpg"
        storage.put_bytes(key, f"frame {index} ".encode() * (50 + index))
        frames.append(Frame(index=index, color_key=key))
    camera = Camera(id=7, sequence_id=3, serial="cam", width=64, height=48)
    etag = bundle_etag(camera, "fingerprint")
    bundle_cache.clear()

    start = threading.Barrier(24)
    results: list[bytes] = []

    def open_page() -> None:
        start.wait()
        results.append(build_bundle(storage, camera, frames, etag))

    pages = [threading.Thread(target=open_page) for _ in range(24)]
    for page in pages:
        page.start()
    for page in pages:
        page.join(30)

    assert len(results) == 24
    assert all(r is results[0] for r in results)  # one build, shared
    assert storage.reads == Counter({f.color_key: 1 for f in frames})
    header, blobs = parse_bundle(results[0])
    assert [e["index"] for e in header["frames"]] == list(range(12))
    assert blobs == [storage.root.joinpath(f.color_key).read_bytes() for f in frames]

    # A later page is served from the cache; a new fingerprint is a new build.
    assert build_bundle(storage, camera, frames, etag) is results[0]
    assert sum(storage.reads.values()) == 12
    build_bundle(storage, camera, frames, bundle_etag(camera, "re-imported"))
    assert sum(storage.reads.values()) == 24
