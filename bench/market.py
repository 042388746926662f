"""Benchmark: the built-in marketplace's Requester API through boto3's real client over HTTP.

Prints a JSON summary on its last line:
    create_hit_per_s            CreateHIT calls per second (ExternalQuestion HITs, 1 assignment)
    publish_1000_s              seconds to create --hits HITs one after another (1,000 by default)
    list_assignments_per_s      ListAssignmentsForHIT calls per second on a HIT with assignments
    get_account_balance_per_s   the cheapest signed call, for reference
    publish_flow_1000_s         seconds for the product's own publish run (what `dexlabel
                                publish` runs: backend.crowd.flows.publish_each, one commit per
                                HIT, botocore retries on) over --hits tasks, scaled to 1,000
    publish_flow_hits_per_s     the same run in HITs per second
Usage: python bench/market.py [--hits 1000] [--calls 200]
"""

from __future__ import annotations

import argparse
import json
import os
import time

from _server import free_port, isolated_workdir, start_server

VIEWS_PER_SEQUENCE = 8  # a DexYCB capture: one hand task per camera view

QUESTION = (
    '<ExternalQuestion xmlns="http://mechanicalturk.amazonaws.com/AWSMechanicalTurkDataSchemas/'
    '2006-07-14/ExternalQuestion.xsd"><ExternalURL>https://example.org/annotate/?task={i}'
    "</ExternalURL><FrameHeight>800</FrameHeight></ExternalQuestion>"
)


def _client(base: str):  # type: ignore[no-untyped-def]
    import boto3
    from botocore.config import Config

    from backend.config import DEV_MARKET_ACCESS_KEY, DEV_MARKET_REQUESTERS

    return boto3.client(
        "mturk", endpoint_url=f"{base}/mturk", region_name="us-east-1",
        aws_access_key_id=DEV_MARKET_ACCESS_KEY,
        aws_secret_access_key=DEV_MARKET_REQUESTERS.split(":", 1)[1],
        config=Config(retries={"max_attempts": 1}),
    )


def _create_hit(mturk, i: int, max_assignments: int = 1) -> str:  # type: ignore[no-untyped-def]
    resp = mturk.create_hit(
        Title=f"Track 21 hand joints ({i})", Description="bench", Reward="0.05",
        LifetimeInSeconds=86400, AssignmentDurationInSeconds=1800,
        Question=QUESTION.format(i=i), MaxAssignments=max_assignments,
        UniqueRequestToken=f"bench-{i}",
    )
    return resp["HIT"]["HITId"]


def _rate(n: int, fn) -> float:  # type: ignore[no-untyped-def]
    t0 = time.perf_counter()
    for _ in range(n):
        fn()
    return n / (time.perf_counter() - t0)


def _make_tasks(count: int) -> None:
    """``count`` hand tasks, 8 views per sequence, written straight into the scratch database."""
    import uuid

    from backend.annotation.models import Task
    from backend.captures.models import Camera, Sequence, Subject
    from backend.db import session_scope

    with session_scope() as session:
        subject = Subject(name="bench-subject")
        for first in range(0, count, VIEWS_PER_SEQUENCE):
            sequence = Sequence(subject=subject, name=f"bench-{first:06d}",
                                storage_uid=uuid.uuid4().hex, num_frames=72,
                                source_kind="images", fingerprint=f"{first:064d}")
            session.add(sequence)
            session.flush()
            for view in range(min(VIEWS_PER_SEQUENCE, count - first)):
                camera = Camera(sequence_id=sequence.id, serial=f"cam{view}", view_index=view,
                                width=640, height=480, fx=600.0, fy=600.0, ppx=320.0,
                                ppy=240.0, distortion=[0.0] * 5,
                                extrinsics=[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]])
                session.add(camera)
                session.flush()
                session.add(Task(sequence_id=sequence.id, camera_id=camera.id, kind="hand",
                                 target_key="hand:0", num_points=21))


def _publish_flow(count: int) -> float:
    """Seconds for ``flows.publish_each`` to publish ``count`` new tasks with the defaults."""
    from backend.config import get_settings
    from backend.crowd import flows
    from backend.crowd.client import make_client
    from backend.crowd.schemas import PublishOptions

    _make_tasks(count)
    client = make_client(get_settings())
    t0 = time.perf_counter()
    result = flows.publish_each(client, PublishOptions(), None)
    seconds = time.perf_counter() - t0
    if result.created != count:
        raise RuntimeError(f"publish created {result.created} HITs, expected {count}")
    return seconds


EPILOG = ("Default run here (2 shared cores): a few minutes at 1,000 HITs (not timed here at"
          " that size); about 1 minute at 10. Short: --hits 10 --calls 5.")


def main() -> None:
    parser = argparse.ArgumentParser(epilog=EPILOG)
    parser.add_argument("--hits", type=int, default=1000)
    parser.add_argument("--calls", type=int, default=200)
    args = parser.parse_args()

    port = free_port()
    # PUBLIC_URL: where the product's client finds the built-in marketplace (/mturk).
    isolated_workdir("market", DEXLABEL_PUBLIC_URL=f"http://127.0.0.1:{port}")
    from backend.config import get_settings
    from backend.migrate import upgrade

    upgrade(get_settings().database_url)
    server, base = start_server(os.environ.copy(), port)
    try:
        mturk = _client(base)
        t0 = time.perf_counter()
        for i in range(args.hits):
            _create_hit(mturk, i)
        publish_s = time.perf_counter() - t0
        hit_id = _create_hit(mturk, args.hits, max_assignments=5)
        list_rate = _rate(args.calls, lambda: mturk.list_assignments_for_hit(
            HITId=hit_id, MaxResults=100))
        balance_rate = _rate(args.calls, mturk.get_account_balance)
        flow_s = _publish_flow(args.hits)
    finally:
        server.terminate()
        server.wait(timeout=20)
    print(json.dumps({
        "benchmark": "market", "hits": args.hits, "calls": args.calls,
        "create_hit_per_s": round(args.hits / publish_s, 1),
        "publish_1000_s": round(publish_s * 1000 / args.hits, 2),
        "list_assignments_per_s": round(list_rate, 1),
        "get_account_balance_per_s": round(balance_rate, 1),
        "publish_flow_1000_s": round(flow_s * 1000 / args.hits, 2),
        "publish_flow_hits_per_s": round(args.hits / flow_s, 1),
    }))


if __name__ == "__main__":
    main()
