"""The AWS path of the crowd client: endpoint selection, the HTTPS rule and error mapping,
with botocore's Stubber where no endpoint can be reached."""

from __future__ import annotations

import pytest
from botocore.stub import Stubber

from backend.config import Settings
from backend.crowd.client import (
    AWS_PRODUCTION_ENDPOINT,
    AWS_SANDBOX_ENDPOINT,
    CrowdConfigError,
    MarketplaceError,
    call,
    credentials,
    endpoint_url,
    make_client,
)

AWS_KEYS = {"mturk_access_key_id": "AKIAEXAMPLEEXAMPLE00",
            "mturk_secret_access_key": "example-secret-example-secret"}


def _settings(**fields: object) -> Settings:
    return Settings(public_url="http://127.0.0.1:8000", **fields)  # type: ignore[arg-type]


def test_default_endpoint_is_the_builtin_marketplace_with_the_dev_pair() -> None:
    settings = _settings()
    assert endpoint_url(settings) == "http://127.0.0.1:8000/mturk"
    assert credentials(settings)[0] == "AKDEXLABELDEVREQUESTER"


@pytest.mark.parametrize(("sandbox", "expected"), [(True, AWS_SANDBOX_ENDPOINT),
                                                   (False, AWS_PRODUCTION_ENDPOINT)])
def test_aws_endpoint_follows_the_sandbox_setting(sandbox: bool, expected: str) -> None:
    client = make_client(_settings(mturk_use_aws=True, mturk_sandbox=sandbox, **AWS_KEYS))
    assert client.meta.endpoint_url == expected
    assert client.meta.region_name == "us-east-1"
    with Stubber(client) as stub:
        stub.add_response("get_account_balance", {"AvailableBalance": "12.34"}, {})
        assert call(client, "get_account_balance")["AvailableBalance"] == "12.34"


def test_any_endpoint_but_the_builtin_one_must_be_https() -> None:
    with pytest.raises(CrowdConfigError, match="must use https"):
        endpoint_url(_settings(mturk_endpoint_url="http://market.example.org/mturk"))
    assert endpoint_url(_settings(mturk_endpoint_url="https://market.example.org/mturk/")) == \
        "https://market.example.org/mturk"
    assert endpoint_url(_settings(mturk_endpoint_url="http://127.0.0.1:8000/mturk")) == \
        "http://127.0.0.1:8000/mturk"


def test_half_a_key_pair_is_refused() -> None:
    with pytest.raises(CrowdConfigError, match="both"):
        credentials(_settings(mturk_access_key_id="AKIAEXAMPLEEXAMPLE00"))


def test_client_errors_become_marketplace_errors_with_the_turk_code() -> None:
    client = make_client(_settings(mturk_use_aws=True, **AWS_KEYS))
    with Stubber(client) as stub:
        stub.add_client_error(
            "approve_assignment", service_error_code="RequestError", http_status_code=400,
            service_message="This operation can be called with a status of: Submitted",
            response_meta={}, modeled_fields={})
        with pytest.raises(MarketplaceError, match="status of: Submitted") as exc:
            call(client, "approve_assignment", AssignmentId="3ABCDEFGHIJ")
    assert exc.value.status_code == 502 and exc.value.operation == "approve_assignment"
