"""Errors of the marketplace, rendered in the MTurk wire format.

MTurk's modelled errors are ``RequestError`` (HTTP 400, the caller's fault) and ``ServiceFault``
(HTTP 500, retryable; botocore retries 5xx). Both carry ``Message`` and ``TurkErrorCode``;
botocore turns ``__type`` into ``ClientError.response["Error"]["Code"]``. Authentication and
framing problems use the generic AWS JSON-protocol error types (``UnrecognizedClientException``
and friends), which carry a lowercase ``message`` and no TurkErrorCode.
"""

from __future__ import annotations

import time
from typing import Any

from backend.errors import DexlabelError

# TurkErrorCodes used across the service (MTurk's own codes where one exists).
PARAMETER_VALIDATION = "ParameterValidationError"
INVALID_PARAMETER = "AWS.MechanicalTurk.InvalidParameterValue"
HIT_DOES_NOT_EXIST = "AWS.MechanicalTurk.HITDoesNotExist"
HIT_TYPE_DOES_NOT_EXIST = "AWS.MechanicalTurk.HITTypeDoesNotExist"
ASSIGNMENT_DOES_NOT_EXIST = "AWS.MechanicalTurk.AssignmentDoesNotExist"
QUALIFICATION_TYPE_DOES_NOT_EXIST = "AWS.MechanicalTurk.QualificationTypeDoesNotExist"
QUALIFICATION_DOES_NOT_EXIST = "AWS.MechanicalTurk.QualificationDoesNotExist"
QUALIFICATION_TYPE_EXISTS = "AWS.MechanicalTurk.QualificationTypeAlreadyExists"
INVALID_HIT_STATE = "AWS.MechanicalTurk.InvalidHITState"
INVALID_ASSIGNMENT_STATE = "AWS.MechanicalTurk.InvalidAssignmentState"
HIT_ALREADY_EXISTS = "AWS.MechanicalTurk.HitAlreadyExists"
DUPLICATE_REQUEST = "AWS.MechanicalTurk.DuplicateRequest"
INSUFFICIENT_FUNDS = "AWS.MechanicalTurk.InsufficientFunds"
INVALID_ASSIGNMENT_INCREASE = "AWS.MechanicalTurk.InvalidMaximumAssignmentsIncrease"
PERMISSION_DENIED = "AWS.MechanicalTurk.PermissionDenied"
DOES_NOT_MEET_REQUIREMENTS = "AWS.MechanicalTurk.DoesNotMeetRequirements"
XML_PARSE_ERROR = "AWS.MechanicalTurk.XMLParseError"
UNSUPPORTED_OPERATION = "AWS.MechanicalTurk.UnsupportedOperation"
SERVICE_UNAVAILABLE = "AWS.ServiceUnavailable"


def _stamp(message: str) -> str:
    # MTurk ends its messages with the server time in epoch milliseconds, e.g. "(1619128282649)".
    return f"{message} ({int(time.time() * 1000)})"


class MarketError(DexlabelError):
    """An error the marketplace answers with; ``body()`` is its JSON wire form."""

    wire_type = "RequestError"
    status_code = 400
    code = "market_error"

    def __init__(self, message: str, turk_code: str | None = None) -> None:
        super().__init__(message)
        self.turk_code = turk_code

    def body(self) -> dict[str, Any]:
        body: dict[str, Any] = {"__type": self.wire_type, "Message": _stamp(self.detail)}
        if self.turk_code:
            body["TurkErrorCode"] = self.turk_code
        return body


class RequestError(MarketError):
    """The request is invalid or not allowed in the current state (HTTP 400)."""


class ServiceFault(MarketError):
    """The marketplace could not process a valid request; the caller may retry (HTTP 500)."""

    wire_type = "ServiceFault"
    status_code = 500


class ProtocolError(MarketError):
    """Authentication or framing failure, in the generic AWS JSON-protocol form."""

    def __init__(self, wire_type: str, message: str, status_code: int = 400) -> None:
        super().__init__(message)
        self.wire_type = wire_type
        self.status_code = status_code

    def body(self) -> dict[str, Any]:
        return {"__type": self.wire_type, "message": self.detail}


def not_found(kind: str, ident: str, turk_code: str) -> RequestError:
    return RequestError(f"{kind} {ident} does not exist.", turk_code)


def invalid(message: str) -> RequestError:
    return RequestError(message, INVALID_PARAMETER)
