"""Login limits: failed password logins counted per account and client address together, per
client address, and per account from every address.

The rule is built so that a stranger cannot lock a real user out, while guessing stays slow:

- ``MAX_ACCOUNT_ADDRESS_FAILURES`` (10) failures for one account (admin or portal, by email,
  whether the account exists or not) from one client address within ``WINDOW_S`` (15 min) lock
  that account for that address only. A guesser at one address therefore stops itself and
  never the owner at another address.
- ``MAX_ADDRESS_FAILURES`` (20) failures from one address within ``WINDOW_S``, whatever the
  accounts, lock that address out of every login.
- ``MAX_ACCOUNT_FAILURES`` (50) failures for one account from all addresses together within
  ``ACCOUNT_WINDOW_S`` (24 h) close the account to every address it has not signed in from
  within ``KNOWN_ADDRESS_S`` (30 days); addresses it has signed in from keep signing in. A
  guesser spread over many addresses gets at most 50 guesses a day at one account; one
  address alone can never close it (its own lock comes first), and the owner at a known
  address is never turned away by it.

A locked login answers 429 with Retry-After, the right password included, until enough of its
failures are older than their window. A successful login forgets that account's failures from
that address and remembers the address as known to the account (its address-wide and
account-wide failures stay). The checks read the same keys for an account that does not exist,
so the answer and its time do not tell whether it exists.

The failures are kept in the process (the embedded deployment has one API process), or in
Redis when ``DEXLABEL_REDIS_URL`` is set, so every API process of a scaled-out deployment
counts the same failures. The client address is the connection's peer, or behind a proxy listed
in ``DEXLABEL_TRUSTED_PROXIES`` the address that proxy forwarded (``client_address``).
"""

from __future__ import annotations

import hashlib
import ipaddress
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, TypeVar

from fastapi import Request

from backend.config import Settings, get_settings
from backend.errors import DexlabelError

WINDOW_S = 15 * 60
MAX_ACCOUNT_ADDRESS_FAILURES = 10
MAX_ADDRESS_FAILURES = 20
ACCOUNT_WINDOW_S = 24 * 3600
MAX_ACCOUNT_FAILURES = 50
KNOWN_ADDRESS_S = 30 * 24 * 3600
T = TypeVar("T")


def now() -> float:
    """The limiter's clock (seconds); the tests move it instead of sleeping."""
    return time.time()


class TooManyAttempts(DexlabelError):
    """Too many failed logins for this account or from this address (429, Retry-After)."""

    status_code = 429
    code = "too_many_attempts"

    def __init__(self, detail: str, retry_after_s: int) -> None:
        super().__init__(detail, retry_after_s=retry_after_s)
        self.headers = {"Retry-After": str(retry_after_s)}


class LimiterUnavailable(DexlabelError, status_code=503, code="login_limiter_unavailable"):
    pass


class FailureStore(Protocol):
    def recent(self, key: str, since: float) -> list[float]:
        """The failure times of ``key`` after ``since``, oldest first."""

    def add(self, key: str, at: float, keep_s: float = WINDOW_S) -> None:
        """Records a time for ``key``, kept at least ``keep_s``."""

    def clear(self, key: str) -> None: ...


class MemoryStore:
    """Failures in this process's memory."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._failures: dict[str, deque[float]] = {}

    def recent(self, key: str, since: float) -> list[float]:
        with self._lock:
            times = self._failures.get(key)
            if times is None:
                return []
            while times and times[0] <= since:
                times.popleft()
            if not times:
                del self._failures[key]
                return []
            return list(times)

    def add(self, key: str, at: float, keep_s: float = WINDOW_S) -> None:
        with self._lock:
            self._failures.setdefault(key, deque()).append(at)

    def clear(self, key: str) -> None:
        with self._lock:
            self._failures.pop(key, None)


class RedisStore:
    """Failures in Redis: one sorted set of failure times per key, expiring with the window.
    The keys are prefixed with the instance (its database URL's digest), so instances sharing
    one Redis count apart."""

    def __init__(self, url: str, instance: str) -> None:
        import redis

        self._redis = redis.Redis.from_url(url)
        self._url = url
        self._prefix = f"dexlabel:login:{hashlib.sha256(instance.encode()).hexdigest()[:12]}:"

    def _call(self, what: str, run: Callable[[], T]) -> T:
        import redis

        try:
            return run()
        except redis.RedisError as exc:
            raise LimiterUnavailable(
                f"the login limiter's Redis cannot be reached ({type(exc).__name__} while "
                f"{what}); check DEXLABEL_REDIS_URL") from exc

    def recent(self, key: str, since: float) -> list[float]:
        name = self._prefix + key

        def run() -> list[float]:
            pipe = self._redis.pipeline()
            pipe.zremrangebyscore(name, "-inf", since)
            pipe.zrange(name, 0, -1, withscores=True)
            return [float(score) for _, score in pipe.execute()[1]]

        return self._call("reading failures", run)

    def add(self, key: str, at: float, keep_s: float = WINDOW_S) -> None:
        name = self._prefix + key

        def run() -> None:
            pipe = self._redis.pipeline()
            pipe.zadd(name, {f"{at:.6f}:{time.monotonic_ns()}": at})
            pipe.expire(name, int(keep_s) + 60)
            pipe.execute()

        self._call("recording a failure", run)

    def clear(self, key: str) -> None:
        self._call("clearing failures", lambda: self._redis.delete(self._prefix + key))


@dataclass(frozen=True)
class Limit:
    key: str
    max_failures: int
    what: str  # "this account from this address", ..., for the refusal
    window_s: float = WINDOW_S
    # Set for the account-wide limit: the key that marks the client address as one the
    # account signed in from; such an address is not held by this limit.
    known_key: str | None = None


class LoginLimiter:
    def __init__(self, store: FailureStore) -> None:
        self.store = store

    @staticmethod
    def limits(realm: str, email: str, address: str) -> tuple[Limit, Limit, Limit]:
        """The limits of one login: the account from this address, the address, and the
        account from every address."""
        account = f"{realm}:{email.strip().lower()}"
        return (Limit(f"account-address:{account}:{address}", MAX_ACCOUNT_ADDRESS_FAILURES,
                      "this account from this address"),
                Limit(f"address:{address}", MAX_ADDRESS_FAILURES, "this address"),
                Limit(f"account:{account}", MAX_ACCOUNT_FAILURES,
                      "this account from addresses it has not signed in from",
                      ACCOUNT_WINDOW_S, f"known:{account}:{address}"))

    def _holds(self, limit: Limit, at: float) -> int | None:
        """Seconds until ``limit`` lets this login through, or None if it does now."""
        failures = self.store.recent(limit.key, at - limit.window_s)
        known = (limit.known_key is not None
                 and bool(self.store.recent(limit.known_key, at - KNOWN_ADDRESS_S)))
        if len(failures) < limit.max_failures or known:
            return None
        # Unlocked once fewer than max_failures remain inside the window.
        free_at = failures[-limit.max_failures] + limit.window_s
        return max(1, math.ceil(free_at - at))

    def check(self, limits: tuple[Limit, ...]) -> None:
        """Raises TooManyAttempts while any of ``limits`` holds this login."""
        at = now()
        waits = []
        for limit in limits:
            wait = self._holds(limit, at)
            if wait is not None:
                waits.append((wait, limit))
        if waits:
            wait, limit = max(waits, key=lambda item: item[0])
            raise TooManyAttempts(
                f"too many failed logins for {limit.what}; try again in {wait} s", wait)

    def failed(self, limits: tuple[Limit, ...]) -> None:
        at = now()
        for limit in limits:
            self.store.add(limit.key, at, limit.window_s)

    def succeeded(self, limits: tuple[Limit, ...]) -> None:
        """A right password: the account's failures from this address are forgotten (the
        address's and the account-wide ones stay), and the address is known to the account."""
        self.store.clear(limits[0].key)
        for limit in limits:
            if limit.known_key is not None:
                self.store.clear(limit.known_key)
                self.store.add(limit.known_key, now(), KNOWN_ADDRESS_S)


_app_lock = threading.Lock()


def _make_limiter(settings: Settings) -> LoginLimiter:
    if settings.redis_url:
        return LoginLimiter(RedisStore(settings.redis_url, settings.database_url))
    return LoginLimiter(MemoryStore())


def login_limiter(request: Request) -> LoginLimiter:
    """The app's limiter (one per app, made on first use)."""
    state = request.app.state
    with _app_lock:
        limiter: LoginLimiter | None = getattr(state, "login_limiter", None)
        if limiter is None:
            limiter = state.login_limiter = _make_limiter(get_settings())
        return limiter


def _trusted(address: str, proxies: list[str]) -> bool:
    try:
        ip = ipaddress.ip_address(address)
    except ValueError:
        return False
    return any(ip in ipaddress.ip_network(block) for block in proxies)


def client_address(request: Request) -> str:
    """The address the login limits count: the connection's peer, unless the peer is a proxy
    of DEXLABEL_TRUSTED_PROXIES; then the right-most X-Forwarded-For address that is not a
    trusted proxy itself (the addresses left of it were written by the client and prove
    nothing). A header from any other peer is ignored, so it cannot be forged."""
    peer = request.client.host if request.client else "unknown"
    proxies = get_settings().trusted_proxies
    if not proxies or not _trusted(peer, proxies):
        return peer
    hops = [hop.strip() for header in request.headers.getlist("x-forwarded-for")
            for hop in header.split(",")]
    for hop in reversed(hops):
        if not hop:
            continue
        try:
            address = str(ipaddress.ip_address(hop))
        except ValueError:
            return peer  # a hop a trusted proxy would not write: count the proxy itself
        if not _trusted(address, proxies):
            return address
    return peer
