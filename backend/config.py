"""Settings: one pydantic-settings class, every field read from ``DEXLABEL_<NAME>``.

The defaults are the embedded deployment: a SQLite file and a local frame folder under ./var,
the SQLite-backed job queue and an in-process consumer. Production points the same fields at
PostgreSQL, Redis and S3 (see docker-compose.yml).
"""

from __future__ import annotations

import dataclasses
import hashlib
import hmac
import ipaddress
import json
import logging
import math
import os
import re
import secrets
import threading
from collections import Counter
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Annotated, Any, Literal
from urllib.parse import urlparse

from pydantic import Field, ValidationError, field_validator, model_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict, SettingsError

from backend.errors import DexlabelError

# Well-known values refused as DEXLABEL_SECRET_KEY in every mode (the former dev default too).
PLACEHOLDER_SECRETS = frozenset({"changeme", "change-me", "secret", "dev-secret-change-me"})
MIN_SECRET_LENGTH = 32
# A prod key must look random: at least this many distinct characters, and by its characters'
# own frequencies (Shannon entropy) this many bits in all and per character. 32 random hex
# digits (`openssl rand -hex 16`) estimate about 115 bits, 3.6 a character (40 random decimal
# digits 3.2); 40 of one letter 0 bits, a word repeated well under 80, a letter repeated with
# some others among it under 2.5 a character.
MIN_SECRET_DISTINCT = 10
MIN_SECRET_BITS = 80.0
MIN_SECRET_BITS_PER_CHAR = 2.5
# With DEXLABEL_SECRET_KEY unset, tokens are signed in dev with a random key made once and kept
# in {VAR_DIR}/secret_key (mode 0600), and in test with the test suite's own key; prod refuses
# to start without one. There is no default key anyone could know.
SECRET_FILE = "secret_key"
TEST_SECRET = "dexlabel-test-suite-signing-key-only-for-env-test"
# The built-in marketplace's requester key pair for local use only; `prod` refuses it.
DEV_MARKET_ACCESS_KEY = "AKDEXLABELDEVREQUESTER"
DEV_MARKET_REQUESTERS = f"{DEV_MARKET_ACCESS_KEY}:dexlabel-dev-requester-secret"
_ACCESS_KEY_RE = re.compile(r"[A-Z0-9]{16,128}")
_AMOUNT_RE = re.compile(r"[0-9]{1,10}(\.[0-9]{1,2})?")


@dataclass(frozen=True)
class MarketRequester:
    """One requester account of the built-in marketplace: a SigV4 key pair and its funds.
    ``unpaid``: its HITs may offer a reward of 0 (the team crowd's account, below)."""

    access_key: str
    secret_key: str
    start_balance_cents: int
    unpaid: bool = False


# Team crowd provider: the lab's own annotators take its units in the worker portal, through the
# built-in marketplace's one unpaid requester account. Its key pair is derived from the signing
# key, which every process of the instance holds, so it needs no setting and nobody without that
# key can use it; it starts with no funds and its HITs pay nothing (team pay is recorded in the
# crowd ledger, never sent anywhere).
TEAM_MARKET_ACCESS_KEY = "AKDEXLABELTEAMREQUESTER"


def team_market_requester(signing_key: str) -> MarketRequester:
    """The team crowd's requester account of the built-in marketplace."""
    secret = hmac.new(signing_key.encode(), b"dexlabel team requester",
                      hashlib.sha256).hexdigest()
    return MarketRequester(TEAM_MARKET_ACCESS_KEY, secret, 0, unpaid=True)


def _cents(amount: str) -> int:
    if not _AMOUNT_RE.fullmatch(amount):
        raise ValueError(f"{amount!r} is not a dollar amount like 100 or 100.00")
    whole, _, frac = amount.partition(".")
    return int(whole) * 100 + int(frac.ljust(2, "0"))


def parse_market_requesters(spec: str, default_balance: str) -> dict[str, MarketRequester]:
    """``"AKID:secret[:balance],..."`` as requesters keyed by access key id."""
    requesters: dict[str, MarketRequester] = {}
    for entry in filter(None, (part.strip() for part in spec.split(","))):
        fields = entry.split(":")
        if len(fields) not in (2, 3) or not fields[1]:
            raise ValueError(
                "DEXLABEL_MARKET_REQUESTERS entries are ACCESS_KEY:SECRET or "
                "ACCESS_KEY:SECRET:BALANCE")
        key = fields[0]
        if not _ACCESS_KEY_RE.fullmatch(key):
            raise ValueError(f"market access key {key!r} must be 16-128 characters A-Z and 0-9")
        if key in requesters:
            raise ValueError(f"market access key {key} is listed twice")
        balance = _cents(fields[2] if len(fields) == 3 else default_balance)
        requesters[key] = MarketRequester(key, fields[1], balance)
    return requesters


def check_qc_thresholds(values: dict[str, Any]) -> dict[str, float | int]:
    """DEXLABEL_QC_THRESHOLDS checked against worker.quality.decide.QCThresholds: every key one
    of its number fields, every value a number of that field's type (whole for an int field),
    finite and positive; the values as that type. ValueError naming the key otherwise."""
    if not values:
        return {}
    # Imported only when the setting is used: the decision module pulls in NumPy, which most
    # CLI commands never load.
    from worker.quality.decide import QCThresholds

    defaults = {f.name: f.default for f in dataclasses.fields(QCThresholds)
                if isinstance(f.default, int | float) and not isinstance(f.default, bool)}
    checked: dict[str, float | int] = {}
    for name, value in values.items():
        if name not in defaults:
            raise ValueError(f"{name!r} is not a QC threshold setting; one of "
                             f"{', '.join(sorted(defaults))}")
        kind = type(defaults[name])
        what = "a whole number" if kind is int else "a number"
        number = isinstance(value, int | float) and not isinstance(value, bool)
        if not number or not math.isfinite(value) or (kind is int and value != int(value)):
            raise ValueError(f"{name} must be {what}, got {value!r}")
        if value <= 0:
            raise ValueError(f"{name} must be above 0, got {value!r}")
        checked[name] = kind(value)
    return checked


class Settings(BaseSettings):
    """All runtime configuration of dexlabel."""

    # hide_input_in_errors: a refused setting's error never repeats the values it was given
    # (the secret key among them).
    model_config = SettingsConfigDict(env_prefix="DEXLABEL_", env_file=".env", extra="ignore",
                                      hide_input_in_errors=True)

    env: Literal["dev", "test", "prod"] = "dev"
    var_dir: Path = Path("var")
    database_url: str = ""
    redis_url: str | None = None
    storage_url: str = ""
    s3_endpoint_url: str | None = None
    s3_region: str = "us-east-1"
    # Frame links on S3 storage: true, presigned URLs of the S3 server that browsers fetch
    # from directly (DEXLABEL_S3_ENDPOINT_URL must then be reachable from browsers); false,
    # the API reads each frame from storage and serves it, so the S3 server can stay private.
    s3_presigned_links: bool = True
    # The address browsers reach the app at: the HITs' page links, invites, the portal's forms.
    public_url: str = "http://127.0.0.1:8000"
    # The address this deployment's own processes (queue workers, the API itself) reach the
    # app's built-in marketplace at, where PUBLIC_URL is not reachable from inside (in a
    # container network: http://api:8000). Unset = PUBLIC_URL.
    internal_url: str | None = None
    # Signs every token; read it through ``signing_key`` (unset: see SECRET_FILE above).
    secret_key: str = Field(default="", repr=False)
    mano_dir: Path | None = None
    # The embedded deployment runs a queue consumer inside `dexlabel serve`; a scale-out
    # deployment turns it off and runs `dexlabel worker` processes instead.
    inprocess_worker: bool = True
    worker_threads: int = Field(default=2, ge=1, le=64)
    # Upper bound on frames served in one per-view bundle (a DexYCB clip has 72).
    max_bundle_frames: int = Field(default=2000, ge=1)
    # The largest frame an import takes, in pixels: checked from the intrinsics and every
    # frame's header before anything is decoded (a 16,000 x 16,000 frame would take ~0.8 GB
    # to decode, and minutes of statistics). DexYCB's frames are 640 x 480.
    max_frame_width: int = Field(default=4096, ge=1, le=65535)
    max_frame_height: int = Field(default=4096, ge=1, le=65535)
    # Folders POST /api/captures/import may read a capture from (the path and the capture's
    # root must lie inside one): a JSON list, or folders separated by os.pathsep (':'); empty =
    # the instance folder's captures/ and the instance folder itself.
    capture_roots: Annotated[list[Path], NoDecode] = Field(default_factory=list)
    # Database concurrency of one server process, sized together (backend/db.py): at most
    # db_pool_size requests work with the database at once, each with its own pooled
    # connection; db_max_overflow more connections serve background work (the in-process
    # queue consumer, the marketplace); a request waits at most db_wait_s for its turn (a
    # connection, or SQLite's single writer) before it is answered 503 with Retry-After. The
    # request threads (http_threads) outnumber the database slots, so a request that holds a
    # connection always finds a thread to finish on. A process runs its Python one thread at
    # a time, so requests beyond the few that cover each other's database waits only share
    # that thread's core and all finish later (bench/load.py, PostgreSQL, 2 processes, 200
    # annotators on 2 cores: save p99 194 ms with 10 at once, 83 with 5, 50 with 4).
    db_pool_size: int = Field(default=4, ge=1, le=1000)
    db_max_overflow: int = Field(default=10, ge=0, le=1000)
    db_wait_s: float = Field(default=5.0, gt=0, le=300)
    http_threads: int = Field(default=40, ge=2, le=1000)
    # PyTorch's intra-op threads in a process that solves (worker.torch_threads reads it where
    # PyTorch loads; unset: 1, or PyTorch's own choice where OMP_NUM_THREADS is set). Declared
    # here so that a bad value stops the server at start rather than failing its jobs.
    torch_threads: int | None = Field(default=None, ge=1, le=1024)
    # Reverse proxies in front of the app (addresses or CIDR blocks; a JSON list or separated
    # by commas). Only a request whose direct peer is one of them has its client address taken
    # from X-Forwarded-For (the right-most address there that is not itself a trusted proxy),
    # for the login limits; empty: the peer is the client and the header is ignored.
    trusted_proxies: Annotated[list[str], NoDecode] = Field(default_factory=list)
    # Requester accounts of the built-in MTurk-compatible marketplace: comma-separated
    # ACCESS_KEY:SECRET[:STARTING_BALANCE]; each key pair is one requester account.
    market_requesters: str = Field(default=DEV_MARKET_REQUESTERS, repr=False)
    market_start_balance: str = "10000.00"
    # Check every marketplace response against botocore's output shape before sending it.
    market_check_responses: bool = True
    # Crowd providers: the one a publish goes to unless it names another (per publish:
    # `dexlabel crowd publish --provider`, the API's PublishRequest.provider).
    crowd_provider: Literal["mturk", "prolific", "team"] = "mturk"
    # The requester side: the MTurk endpoint HITs are published to. Unset = the built-in
    # marketplace at {PUBLIC_URL}/mturk; any other endpoint must be HTTPS.
    mturk_endpoint_url: str | None = None
    # Unset = the built-in marketplace's dev requester pair.
    mturk_access_key_id: str | None = None
    mturk_secret_access_key: str | None = Field(default=None, repr=False)
    # With an AWS endpoint (mturk_endpoint_url unset and mturk_use_aws): sandbox or production.
    mturk_sandbox: bool = True
    mturk_use_aws: bool = False
    # Prolific (backend.crowd.providers.prolific): the API token ("Authorization: Token ..."),
    # the API's address, the workspace that owns studies and webhook subscriptions, and the
    # secret that signs Prolific's webhooks to us; a webhook whose timestamp is older than
    # prolific_webhook_max_age_s is refused. The pay floor: a unit whose reward for its
    # expected time pays under prolific_min_hourly_rate (in prolific_currency, an hour) is
    # refused before any call (Prolific's own minimum: GBP 6.00 / USD 8.00 an hour). The fee:
    # Prolific's service fee on rewards and bonuses (33.3 % at the time of writing).
    prolific_token: str | None = Field(default=None, repr=False)
    prolific_api_url: str = "https://api.prolific.com"
    prolific_workspace_id: str | None = None
    prolific_webhook_secret: str | None = Field(default=None, repr=False)
    prolific_webhook_max_age_s: float = Field(default=300.0, gt=0)
    prolific_min_hourly_rate: float = Field(default=6.0, ge=0)
    prolific_currency: Literal["GBP", "USD"] = "GBP"
    prolific_fee_rate: float = Field(default=0.333, ge=0, le=1)
    # Days an export's archive is kept in storage after the export finished; the hourly
    # clean-up job deletes older ones (0: keep them all).
    export_retention_days: float = Field(default=7.0, ge=0)
    # This host's name in the job table (which host ran each job, as "name:pid"); unset, the
    # machine's hostname.
    host_name: str | None = Field(default=None, max_length=200)
    # Queue jobs (QC, solve): attempts before "failed", the first retry delay (doubled each
    # attempt), and the lease a running job holds; a job whose lease ran out (its worker died)
    # is queued again by the reaper. A lost queue message is re-sent after job_requeue_after_s.
    job_max_attempts: int = Field(default=5, ge=1, le=50)
    job_retry_base_s: float = Field(default=5.0, ge=0)
    # A minute's lease, renewed by the attempt's heartbeat every quarter of it, and a reaper
    # pass every half minute: a killed worker's job is taken over within about 90 s.
    job_lease_s: float = Field(default=60.0, gt=0)
    job_requeue_after_s: float = Field(default=600.0, gt=0)
    # Pause this long at each checkpoint of a job (between the QC job's actions): a
    # fault-injection knob for the crash-recovery test and drills (kill a worker mid-job);
    # 0 in every real deployment.
    job_pause_s: float = Field(default=0.0, ge=0)
    # Solve jobs: the optimiser when a request names none ("default" = batched
    # Levenberg-Marquardt from triangulation, "paper" = DexYCB's per-frame Adam), and the torch
    # device the solver runs on ("cpu", or "cuda" where a GPU is present).
    solve_optimiser: Literal["paper", "default"] = "default"
    solve_device: str = "cpu"
    # The deployment's solver settings (energy weights w_kpt, w_depth, w_reg, w_smooth, robust
    # scales, iterations: worker.solver.SolveSettings fields) as JSON, e.g.
    # DEXLABEL_SOLVE_PARAMS='{"w_depth": 5.0}'; a solve request's own params come on top.
    solve_params: dict[str, float | int | bool] = Field(default_factory=dict)
    # Quality control: act on clear decisions (approve / reject + re-open) without an admin;
    # block a worker after this many rejected assignments (0: never); the settings of the
    # learned thresholds as JSON of worker.quality.decide.QCThresholds' number fields
    # (k_review, k_reject, min_population, motion_ratio_high), e.g.
    # DEXLABEL_QC_THRESHOLDS='{"k_review": 2.5}'; an unknown key or a wrong type is refused
    # when the settings load (check_qc_thresholds).
    qc_auto_actions: bool = True
    qc_block_after_failures: int = Field(default=3, ge=0)
    qc_thresholds: dict[str, Any] = Field(default_factory=dict)
    # Publishing views (backend.crowd.adaptive): "every-view" publishes every (target, view)
    # task at once (DexYCB's protocol); "adaptive" publishes, per target, the
    # PUBLISH_INITIAL_VIEWS views of widest baseline first and one more view after each solve
    # while fewer than PUBLISH_CONFIDENT_SHARE of the target's frames have a solve confidence
    # of at least PUBLISH_CONFIDENCE without a flag. A publish request may set its own.
    publish_policy: Literal["every-view", "adaptive"] = "every-view"
    publish_initial_views: int = Field(default=3, ge=2, le=64)
    publish_confidence: float = Field(default=0.5, gt=0, le=1)
    publish_confident_share: float = Field(default=0.9, gt=0, le=1)

    @field_validator("capture_roots", mode="before")
    @classmethod
    def _split_capture_roots(cls, value: Any) -> Any:
        """A JSON list of folders, or folders separated by os.pathsep."""
        if not isinstance(value, str):
            return value
        text = value.strip()
        if text.startswith("["):
            return json.loads(text)
        return [part.strip() for part in text.split(os.pathsep) if part.strip()]

    @field_validator("internal_url")
    @classmethod
    def _check_internal_url(cls, value: str | None) -> str | None:
        if not value:
            return None
        if urlparse(value).scheme not in ("http", "https") or not urlparse(value).netloc:
            raise ValueError("must be an http:// or https:// address, e.g. http://api:8000")
        return value.rstrip("/")

    @field_validator("trusted_proxies", mode="before")
    @classmethod
    def _split_trusted_proxies(cls, value: Any) -> Any:
        if isinstance(value, str):
            text = value.strip()
            value = (json.loads(text) if text.startswith("[")
                     else [part.strip() for part in text.split(",") if part.strip()])
        if not isinstance(value, list):
            raise ValueError("must be a list of addresses or CIDR blocks")
        checked = []
        for item in value:
            try:
                checked.append(str(ipaddress.ip_network(str(item).strip(), strict=False)))
            except ValueError:
                raise ValueError(f"{str(item)[:64]!r} is not an IP address or CIDR block") \
                    from None
        return checked

    @field_validator("qc_thresholds")
    @classmethod
    def _check_qc_thresholds(cls, value: dict[str, Any]) -> dict[str, float | int]:
        return check_qc_thresholds(value)

    @model_validator(mode="after")
    def _fill_defaults_and_check(self) -> Settings:
        if not self.database_url:
            self.database_url = f"sqlite:///{(self.var_dir / 'dexlabel.db').as_posix()}"
        if not self.storage_url:
            self.storage_url = (self.var_dir / "storage").as_posix()
        if self.http_threads <= self.db_pool_size:
            raise ValueError(
                f"DEXLABEL_HTTP_THREADS ({self.http_threads}) must be above DEXLABEL_DB_POOL_SIZE "
                f"({self.db_pool_size}): a request holding a connection needs a free thread")
        # The messages name the setting, never its value.
        secret = self.secret_key.strip()
        if secret.lower() in PLACEHOLDER_SECRETS:
            raise ValueError("DEXLABEL_SECRET_KEY is a well-known placeholder; set a long random "
                             "value (or leave it unset in dev)")
        if self.env == "prod" and not secret:
            raise ValueError(f"DEXLABEL_SECRET_KEY is not set; prod needs {MIN_SECRET_LENGTH} or "
                             "more random characters (e.g. `openssl rand -hex 32`)")
        if self.env == "prod" and len(secret) < MIN_SECRET_LENGTH:
            raise ValueError(f"DEXLABEL_SECRET_KEY is too short; prod needs {MIN_SECRET_LENGTH} "
                             "or more random characters")
        if self.env == "prod":
            _check_secret_randomness(secret)
        if self.env == "dev" and not secret and self.shared_deployment:
            raise ValueError(
                "DEXLABEL_SECRET_KEY is not set; a deployment on PostgreSQL or Redis runs on "
                "several hosts, which must all sign with one key: set it on every host (e.g. "
                "`openssl rand -hex 32`)")
        requesters = parse_market_requesters(self.market_requesters, self.market_start_balance)
        if TEAM_MARKET_ACCESS_KEY in requesters:
            raise ValueError(f"DEXLABEL_MARKET_REQUESTERS lists {TEAM_MARKET_ACCESS_KEY}, the team "
                             "crowd's own account; choose another access key")
        if self.env == "prod":
            if DEV_MARKET_ACCESS_KEY in requesters:
                raise ValueError("DEXLABEL_MARKET_REQUESTERS holds the dev key pair; set real ones")
            if any(len(r.secret_key) < 20 for r in requesters.values()):
                raise ValueError("market secret keys must be at least 20 characters outside dev")
        return self

    @property
    def signing_key(self) -> str:
        """The key that signs tokens and seeds request tokens: DEXLABEL_SECRET_KEY, or unset,
        the test suite's key in test and this instance's own random key in dev."""
        if self.secret_key.strip():
            return self.secret_key.strip()
        if self.env == "test":
            return TEST_SECRET
        return instance_secret(self.var_dir)

    @property
    def shared_deployment(self) -> bool:
        """Whether hosts other than this one may serve or work for this instance: its database
        or queue is a server (PostgreSQL, Redis). Such hosts share nothing on disk, so a key
        kept in the instance folder (the embedded default's) would differ on each."""
        return bool(self.redis_url) or not self.is_sqlite

    @property
    def queue_path(self) -> Path:
        """SQLite file of the embedded job queue (used when REDIS_URL is unset)."""
        return self.var_dir / "queue.db"

    @property
    def market_requester_accounts(self) -> dict[str, MarketRequester]:
        """The marketplace's requester accounts keyed by access key id."""
        return parse_market_requesters(self.market_requesters, self.market_start_balance)

    @property
    def market_accounts(self) -> dict[str, MarketRequester]:
        """Every requester account the marketplace answers, keyed by access key id: those of
        DEXLABEL_MARKET_REQUESTERS and the team crowd's."""
        team = team_market_requester(self.signing_key)
        return {**self.market_requester_accounts, team.access_key: team}

    @property
    def is_sqlite(self) -> bool:
        return self.database_url.startswith("sqlite")


def secret_bits(secret: str) -> float:
    """An estimate of a key's randomness in bits: its length times the Shannon entropy of its
    characters' frequencies (a key of one repeated letter has 0)."""
    if not secret:
        return 0.0
    counts = Counter(secret)
    n = len(secret)
    return -n * sum(c / n * math.log2(c / n) for c in counts.values())


def _check_secret_randomness(secret: str) -> None:
    distinct = len(set(secret))
    bits = secret_bits(secret)
    if (distinct < MIN_SECRET_DISTINCT or bits < MIN_SECRET_BITS
            or bits < MIN_SECRET_BITS_PER_CHAR * len(secret)):
        raise ValueError(
            f"DEXLABEL_SECRET_KEY does not look random ({distinct} distinct characters, about "
            f"{bits:.0f} bits); prod needs at least {MIN_SECRET_DISTINCT} distinct characters "
            f"and {MIN_SECRET_BITS:.0f} bits ({MIN_SECRET_BITS_PER_CHAR} a character): use a "
            "random value (e.g. `openssl rand -hex 32`)")


class InvalidSettings(DexlabelError, status_code=500, code="invalid_settings"):
    """The environment's settings are refused; the detail names each variable and why, one
    per line (``DEXLABEL_QC_THRESHOLDS: 'x' is not a QC threshold setting; ...``). A
    deployment's fault, not a request's: status 500. The CLI prints it without a traceback."""


def _describe(exc: ValidationError) -> str:
    lines = []
    for error in exc.errors():
        message = error["msg"].removeprefix("Value error, ")
        field = str(error["loc"][0]) if error["loc"] else ""
        lines.append(f"DEXLABEL_{field.upper()}: {message}" if field else message)
    return "\n".join(lines)


# The instance folder holds the database, the queue, the signing key, export archives and
# the stored frames: readable by its owner only, so its files need no mode of their own.
INSTANCE_FOLDER_MODE = 0o700


def keep_instance_private(var_dir: Path) -> None:
    """Make the instance folder (if missing) with mode 0700, or take group's and others'
    access from one that has it. A folder this process may not change (a volume owned by
    another user) is left as it is, with a warning."""
    try:
        var_dir.mkdir(mode=INSTANCE_FOLDER_MODE, parents=True, exist_ok=True)
        if var_dir.stat().st_mode & 0o077:
            os.chmod(var_dir, INSTANCE_FOLDER_MODE)
    except OSError as exc:
        logging.getLogger(__name__).warning(
            "the instance folder %s cannot be made private (mode 0700): %s", var_dir, exc)


_secret_lock = threading.Lock()
_instance_secrets: dict[Path, str] = {}


def instance_secret(var_dir: Path) -> str:
    """The dev instance's signing key, kept in ``{var_dir}/secret_key`` (mode 0600): read, or
    made once (a random 64-character key) the first time any process of the instance needs
    it. Every process of the instance reads the same file, so they all sign alike."""
    path = (var_dir / SECRET_FILE).absolute()
    with _secret_lock:
        key = _instance_secrets.get(path)
        if key is None:
            key = _instance_secrets[path] = _read_or_make_secret(path)
        return key


def _read_or_make_secret(path: Path) -> str:
    if not path.exists():
        keep_instance_private(path.parent)
        # Written whole under a temporary name, then linked into place: a process racing this
        # one reads either no file or the whole key, and the first link wins.
        temp = path.with_name(f".{SECRET_FILE}.{os.getpid()}.{secrets.token_hex(4)}")
        fd = os.open(temp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "w") as out:
            out.write(secrets.token_urlsafe(48) + "\n")
        try:
            os.link(temp, path)
        except FileExistsError:
            pass
        finally:
            os.unlink(temp)
    if path.stat().st_mode & 0o077:
        os.chmod(path, 0o600)
    key = path.read_text().strip()
    if len(key) < MIN_SECRET_LENGTH:
        raise InvalidSettings(f"{path} does not hold a signing key (too short); delete it and "
                              "a new one is made")
    return key


@lru_cache
def get_settings() -> Settings:
    """The process-wide settings, read once from the environment.

    Raises InvalidSettings naming every refused variable (a wrong value, an unknown key of a
    JSON setting, JSON that does not parse), so a process refuses to start with them.
    """
    try:
        return Settings()
    except ValidationError as exc:
        raise InvalidSettings(_describe(exc)) from None
    except SettingsError as exc:  # a JSON setting that does not parse
        field = re.search(r'field "(\w+)"', str(exc))
        name = f"DEXLABEL_{field.group(1).upper()}" if field else "a setting"
        raise InvalidSettings(f"{name} is not valid JSON: {exc.__cause__ or exc}") from None
