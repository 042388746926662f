"""Benchmark: synthesise and import a default capture, then serve its frames per view.

Prints a JSON summary on its last line:
    synth_s, import_s            seconds for `generate_capture` and `import_path` (8 x 72 default)
    bundle_cold_fps              frames per second served by the per-view bundle endpoint over
                                 real HTTP, first request of each view (read from storage)
    bundle_warm_fps              the same, repeated requests (bundle cache hot)
    single_frame_fps             frames per second fetching frame JPEGs one request at a time
Usage: python bench/import.py [--frames 72] [--views 8] [--rounds 5]
"""

from __future__ import annotations

import argparse
import json
import os
import time
import urllib.request

from _server import isolated_workdir, start_server


def _get(url: str, token: str) -> bytes:
    req = urllib.request.Request(url, headers={"Authorization": f"Bearer {token}"})
    with urllib.request.urlopen(req) as resp:
        return resp.read()


EPILOG = ("Default run here (2 shared cores): about 3-4 minutes (the 8 x 72 capture's"
          " synthesis is most of it). Short: --frames 6 --views 2 --rounds 1.")


def main() -> None:
    parser = argparse.ArgumentParser(epilog=EPILOG)
    parser.add_argument("--frames", type=int, default=72)
    parser.add_argument("--views", type=int, default=8)
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()

    work = isolated_workdir("import")

    from backend.accounts.service import create_admin
    from backend.captures.flows import import_path
    from backend.config import get_settings
    from backend.db import session_scope
    from backend.migrate import upgrade
    from worker.synth import generate_capture

    t0 = time.perf_counter()
    summary = generate_capture(work / "capture", seed=7, frames=args.frames, views=args.views)
    synth_s = time.perf_counter() - t0
    upgrade(get_settings().database_url)
    t0 = time.perf_counter()
    result = import_path(work / "capture")[0]
    import_s = time.perf_counter() - t0
    with session_scope() as s:
        create_admin(s, "bench@example.org", "bench-password-123")

    server, base = start_server(os.environ.copy())
    try:
        body = json.dumps({"email": "bench@example.org", "password": "bench-password-123"}).encode()
        req = urllib.request.Request(f"{base}/api/auth/token", data=body,
                                     headers={"Content-Type": "application/json"})
        token = json.loads(urllib.request.urlopen(req).read())["access_token"]
        views = [f"{base}/api/sequences/{result.sequence_id}/views/{s}" for s in summary.serials]

        t0 = time.perf_counter()
        cold_bytes = sum(len(_get(f"{v}/frames.bin", token)) for v in views)
        cold_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        for _ in range(args.rounds):
            for v in views:
                _get(f"{v}/frames.bin", token)
        warm_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        for i in range(args.frames):
            _get(f"{views[0]}/frames/{i}.jpg", token)
        single_s = time.perf_counter() - t0
    finally:
        server.terminate()
        server.wait(timeout=20)

    frames_per_round = args.frames * len(views)
    print(json.dumps({
        "benchmark": "import",
        "views": len(views), "frames": args.frames,
        "synth_s": round(synth_s, 2), "import_s": round(import_s, 2),
        "bundle_mb_per_view": round(cold_bytes / len(views) / 1e6, 2),
        "bundle_cold_fps": round(frames_per_round / cold_s, 1),
        "bundle_warm_fps": round(frames_per_round * args.rounds / warm_s, 1),
        "single_frame_fps": round(args.frames / single_s, 1),
    }))


if __name__ == "__main__":
    main()
