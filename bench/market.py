"""Benchmark: the built-in marketplace's Requester API through boto3's real client over HTTP.

Prints a JSON summary on its last line:
    create_hit_per_s            CreateHIT calls per second (ExternalQuestion HITs, 1 assignment)
    publish_1000_s              seconds to create --hits HITs one after another (1,000 by default)
    list_assignments_per_s      ListAssignmentsForHIT calls per second on a HIT with assignments
    get_account_balance_per_s   the cheapest signed call, for reference
Usage: python bench/market.py [--hits 1000] [--calls 200]
"""

from __future__ import annotations

import argparse
import json
import os
import time

from _server import isolated_workdir, start_server

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


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--hits", type=int, default=1000)
    parser.add_argument("--calls", type=int, default=200)
    args = parser.parse_args()

    isolated_workdir("market")
    from backend.config import get_settings
    from backend.migrate import upgrade

    upgrade(get_settings().database_url)
    server, base = start_server(os.environ.copy())
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
    finally:
        server.terminate()
        server.wait(timeout=20)
    print(json.dumps({
        "benchmark": "market", "hits": args.hits, "calls": args.calls,
        "create_hit_per_s": round(args.hits / publish_s, 1),
        "publish_1000_s": round(publish_s * 1000 / args.hits, 2),
        "list_assignments_per_s": round(list_rate, 1),
        "get_account_balance_per_s": round(balance_rate, 1),
    }))


if __name__ == "__main__":
    main()
