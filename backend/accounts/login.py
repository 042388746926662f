"""Password login shared by admins (``/api/auth/token``) and portal workers
(``/api/portal/login``): the login limits, one scrypt check whether or not the account exists,
and the account's token epoch for the token it gets.

The endpoints are async: the account is read in a request thread, the password is checked in
one of the password-check threads (``backend.security.check_password``), so logins waiting for
a check hold no request thread and never slow down the other requests.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from fastapi import Request
from starlette.concurrency import run_in_threadpool

from backend.accounts.limits import Limit, LoginLimiter, client_address, login_limiter
from backend.errors import Unauthorized
from backend.security import check_password

WRONG = "email or password is wrong"


@dataclass(frozen=True)
class LoginRecord:
    """What a login needs of an account, read before the password is checked."""

    account_id: int
    password_hash: str
    active: bool
    token_epoch: int
    worker_id: str | None = None  # a portal account's marketplace worker id


def _locked_or_found(limiter: LoginLimiter, limits: tuple[Limit, ...],
                     find: Callable[[str], LoginRecord | None], email: str) -> LoginRecord | None:
    limiter.check(limits)
    return find(email)


async def password_login(request: Request, realm: str, email: str, password: str,
                         find: Callable[[str], LoginRecord | None]) -> LoginRecord:
    """The account ``find`` reads for ``email`` if ``password`` is its password and it is
    active; Unauthorized otherwise (the same answer, in the same time, for an unknown email),
    and TooManyAttempts while the account or the client address is locked out."""
    limiter = login_limiter(request)
    limits = limiter.limits(realm, email, client_address(request))
    found = await run_in_threadpool(_locked_or_found, limiter, limits, find, email)
    ok = await check_password(password, found.password_hash if found is not None else None)
    if not ok or found is None or not found.active:
        await run_in_threadpool(limiter.failed, limits)
        raise Unauthorized(WRONG)
    await run_in_threadpool(limiter.succeeded, limits)
    return found


async def password_check(request: Request, realm: str, email: str, password: str,
                         stored: str) -> None:
    """A signed-in account's current password, checked under the same limits as a login
    (for a password change); Unauthorized when it is wrong."""
    limiter = login_limiter(request)
    limits = limiter.limits(realm, email, client_address(request))
    await run_in_threadpool(limiter.check, limits)
    if not await check_password(password, stored):
        await run_in_threadpool(limiter.failed, limits)
        raise Unauthorized("the current password is wrong")
