"""Login limits: failed password logins counted per account and per client address.

``MAX_ACCOUNT_FAILURES`` failures for one account (admin or portal, by email, whether the
account exists or not) or ``MAX_ADDRESS_FAILURES`` from one client address within
``WINDOW_S`` lock that account or address out: every login it tries answers 429 with
Retry-After, the right password included, until enough of those failures are older than the
window. A successful login clears its account's failures (not its address's).

The failures are kept in the process (the embedded deployment has one API process), or in
Redis when ``DEXLABEL_REDIS_URL`` is set, so every API process of a scaled-out deployment
counts the same failures.
"""

from __future__ import annotations

import hashlib
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
MAX_ACCOUNT_FAILURES = 10
MAX_ADDRESS_FAILURES = 20
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


class LimiterUnavailable(DexlabelError):
    status_code = 503
    code = "login_limiter_unavailable"


class FailureStore(Protocol):
    def recent(self, key: str, since: float) -> list[float]:
        """The failure times of ``key`` after ``since``, oldest first."""

    def add(self, key: str, at: float) -> None: ...

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

    def add(self, key: str, at: float) -> None:
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

    def add(self, key: str, at: float) -> None:
        name = self._prefix + key

        def run() -> None:
            pipe = self._redis.pipeline()
            pipe.zadd(name, {f"{at:.6f}:{time.monotonic_ns()}": at})
            pipe.expire(name, WINDOW_S + 60)
            pipe.execute()

        self._call("recording a failure", run)

    def clear(self, key: str) -> None:
        self._call("clearing failures", lambda: self._redis.delete(self._prefix + key))


@dataclass(frozen=True)
class Limit:
    key: str
    max_failures: int
    what: str  # "this account" / "this address", for the refusal


class LoginLimiter:
    def __init__(self, store: FailureStore) -> None:
        self.store = store

    @staticmethod
    def limits(realm: str, email: str, address: str) -> tuple[Limit, Limit]:
        """The account's and the client address's limits of one login."""
        account = email.strip().lower()
        return (Limit(f"account:{realm}:{account}", MAX_ACCOUNT_FAILURES, "this account"),
                Limit(f"address:{address}", MAX_ADDRESS_FAILURES, "this address"))

    def check(self, limits: tuple[Limit, ...]) -> None:
        """Raises TooManyAttempts while any of ``limits`` is locked out."""
        at = now()
        waits = []
        for limit in limits:
            failures = self.store.recent(limit.key, at - WINDOW_S)
            if len(failures) >= limit.max_failures:
                # Unlocked once fewer than max_failures remain inside the window.
                free_at = failures[-limit.max_failures] + WINDOW_S
                waits.append((max(1, math.ceil(free_at - at)), limit))
        if waits:
            wait, limit = max(waits, key=lambda item: item[0])
            raise TooManyAttempts(
                f"too many failed logins for {limit.what}; try again in {wait} s", wait)

    def failed(self, limits: tuple[Limit, ...]) -> None:
        at = now()
        for limit in limits:
            self.store.add(limit.key, at)

    def succeeded(self, limits: tuple[Limit, ...]) -> None:
        """A right password: the account's failures are forgotten (the address's stay)."""
        self.store.clear(limits[0].key)


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


def client_address(request: Request) -> str:
    return request.client.host if request.client else "unknown"
