"""docker-compose.yml as written: Debian's `docker-compose` (1.29) validates and resolves it with
every secret set and refuses it naming each one missing; only the API listens on a public
interface; no password has a default or a literal value; the app does not use MinIO's root
user; every volume and mount is used. No image is pulled and nothing is started."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path
from typing import Any

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[2]
COMPOSE_FILE = ROOT / "docker-compose.yml"
# Every secret the deployment needs, with a value of the form each one asks for.
SECRETS = {
    "POSTGRES_PASSWORD": "4f1c0de5a7e2b9d3c8a6f0e1d2c3b4a5",
    "DEXLABEL_SECRET_KEY": "9b2e7f4a1c8d3e6f0a5b2c9d4e7f1a3b6c8d0e2f4a6b8c0d",
    "DEXLABEL_MTURK_ACCESS_KEY_ID": "AKLAB0A1B2C3D4E5F6A",
    "DEXLABEL_MTURK_SECRET_ACCESS_KEY": "0f1e2d3c4b5a69788796a5b4c3d2e1f0",
    "MINIO_ROOT_USER": "minio-admin",
    "MINIO_ROOT_PASSWORD": "c3d4e5f60718293a4b5c6d7e",
    "DEXLABEL_S3_ACCESS_KEY": "dexlabel-app",
    "DEXLABEL_S3_SECRET_KEY": "a1b2c3d4e5f60718293a4b5c",
}
LOOPBACK = {"127.0.0.1", "::1", "localhost"}
# Environment names that hold a secret.
SECRET_NAME = re.compile(r"PASSWORD|SECRET|_KEY(_ID)?$")
REQUIRED_REFERENCE = re.compile(r"^\$\{(\w+):\?[^}]+\}$")


def _docker_compose() -> str:
    found = shutil.which("docker-compose")
    if found is None:
        if os.environ.get("CI") == "true":
            pytest.fail("docker-compose is required in CI (tests/run.sh installs Debian's)")
        pytest.skip("docker-compose is not installed (apt-get install docker-compose)")
    return found


def _config(tmp_path: Path, values: dict[str, str]) -> subprocess.CompletedProcess[str]:
    """`docker-compose config` with exactly ``values`` as the deployment's settings: nothing
    from this shell's environment or from an .env file beside the compose file."""
    env_file = tmp_path / "compose.env"
    env_file.write_text("".join(f"{k}={v}\n" for k, v in values.items()))
    env = {k: v for k, v in os.environ.items()
           if k not in SECRETS and not k.startswith(("DEXLABEL_", "MINIO_", "POSTGRES_"))}
    return subprocess.run(
        [_docker_compose(), "--env-file", str(env_file), "-f", str(COMPOSE_FILE), "config"],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120, check=False)


@pytest.fixture(scope="module")
def written() -> dict[str, Any]:
    """The compose file as written (before any interpolation)."""
    parsed: dict[str, Any] = yaml.safe_load(COMPOSE_FILE.read_text())
    return parsed


@pytest.fixture(scope="module")
def resolved(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    done = _config(tmp_path_factory.mktemp("compose"), SECRETS)
    assert done.returncode == 0, done.stderr
    parsed: dict[str, Any] = yaml.safe_load(done.stdout)
    return parsed


def test_the_compose_file_resolves_with_every_secret_set(resolved: dict[str, Any]) -> None:
    services = resolved["services"]
    assert {"postgres", "redis", "minio", "minio-init", "migrate", "api", "worker"} <= set(
        services)
    for role in ("migrate", "api", "worker"):
        env = services[role]["environment"]
        assert env["DEXLABEL_SECRET_KEY"] == SECRETS["DEXLABEL_SECRET_KEY"]
        assert env["DEXLABEL_MTURK_ACCESS_KEY_ID"] == SECRETS["DEXLABEL_MTURK_ACCESS_KEY_ID"]
        assert env["DEXLABEL_MTURK_SECRET_ACCESS_KEY"] == SECRETS[
            "DEXLABEL_MTURK_SECRET_ACCESS_KEY"]
        # The requester pair is the built-in marketplace's requester account.
        assert env["DEXLABEL_MARKET_REQUESTERS"] == (
            f"{SECRETS['DEXLABEL_MTURK_ACCESS_KEY_ID']}:"
            f"{SECRETS['DEXLABEL_MTURK_SECRET_ACCESS_KEY']}")
        assert f":{SECRETS['POSTGRES_PASSWORD']}@postgres:" in env["DEXLABEL_DATABASE_URL"]
        # Containers reach the app by its service name; browsers by the public address.
        assert env["DEXLABEL_INTERNAL_URL"] == "http://api:8000"
        assert env["DEXLABEL_PUBLIC_URL"] != env["DEXLABEL_INTERNAL_URL"]
        assert env["DEXLABEL_S3_PRESIGNED_LINKS"] == "false"  # MinIO is not published
        # The app's MinIO user is not the root user.
        assert env["AWS_ACCESS_KEY_ID"] == SECRETS["DEXLABEL_S3_ACCESS_KEY"]
        assert env["AWS_ACCESS_KEY_ID"] != SECRETS["MINIO_ROOT_USER"]
    assert services["api"]["environment"]["DEXLABEL_CAPTURE_ROOTS"] == "/captures"
    assert "--workers" in services["api"]["command"]


@pytest.mark.parametrize("missing", sorted(SECRETS))
def test_the_compose_file_refuses_to_run_without_each_secret(tmp_path: Path,
                                                             missing: str) -> None:
    done = _config(tmp_path, {k: v for k, v in SECRETS.items() if k != missing})
    assert done.returncode != 0
    assert f"set {missing} " in done.stderr, done.stderr


def test_without_any_secret_the_refusal_names_one(tmp_path: Path) -> None:
    done = _config(tmp_path, {})
    assert done.returncode != 0
    assert any(f"set {name} " in done.stderr for name in SECRETS), done.stderr


def _host_ip(port: Any) -> str:
    """The host address a published port binds ('' = every interface)."""
    if isinstance(port, dict):  # the long form
        return str(port.get("host_ip", ""))
    text = str(port).rsplit("/", 1)[0]
    parts = text.rsplit(":", 2)
    return parts[0] if len(parts) == 3 else ""


def test_only_the_api_listens_on_a_public_interface(resolved: dict[str, Any]) -> None:
    public = {name: service["ports"] for name, service in resolved["services"].items()
              if any(_host_ip(p) not in LOOPBACK for p in service.get("ports", []))}
    assert list(public) == ["api"], public
    assert all(":8000" in str(p) for p in public["api"])
    # The MinIO console, if published at all, only on this host's loopback.
    for port in resolved["services"]["minio"].get("ports", []):
        assert _host_ip(port) in LOOPBACK, port


def _environments(written: dict[str, Any]) -> list[tuple[str, dict[str, Any]]]:
    found = [("x-dexlabel-env", written["x-dexlabel-env"])]
    for name, service in written["services"].items():
        env = service.get("environment") or {}
        assert isinstance(env, dict), f"{name}: write environment as a mapping"
        found.append((name, env))
    return found


def test_no_secret_has_a_literal_value_or_a_default(written: dict[str, Any]) -> None:
    text = COMPOSE_FILE.read_text()
    for name in SECRETS:
        assert not re.search(rf"\$\{{{name}:?-", text), f"{name} has a default"
    for where, env in _environments(written):
        for key, value in env.items():
            if not SECRET_NAME.search(key) or key == "DEXLABEL_MARKET_REQUESTERS":
                continue
            match = REQUIRED_REFERENCE.match(str(value))
            assert match, f"{where}: {key} must be ${{VAR:?message}}, not {value!r}"
            assert match.group(1) in SECRETS, f"{where}: {key} reads {match.group(1)}"
    # The database URL carries the password only by reference.
    url = written["x-dexlabel-env"]["DEXLABEL_DATABASE_URL"]
    assert re.search(r":\$\{POSTGRES_PASSWORD:\?[^}]+\}@", url), url


def test_every_volume_is_used_and_every_mount_is_needed(written: dict[str, Any]) -> None:
    declared = set(written.get("volumes") or {})
    mounted: set[str] = set()
    binds: dict[str, list[str]] = {}
    for name, service in written["services"].items():
        for volume in service.get("volumes", []):
            spec = re.sub(r":(ro|rw)$", "", str(volume))
            source, target = spec.rsplit(":", 1)
            if source.startswith((".", "/", "$")):
                binds.setdefault(name, []).append(target)
            else:
                assert source in declared, f"{name} mounts undeclared volume {source}"
                mounted.add(source)
    assert declared == mounted, f"unused volumes: {declared - mounted}"
    # The only folder from the host: the captures the API imports from (workers read only
    # storage).
    assert binds == {"api": ["/captures"]}, binds
    roots = written["x-dexlabel-env"]["DEXLABEL_CAPTURE_ROOTS"].split(":")
    assert "/captures" in roots


def test_the_bucket_policy_limits_the_app_to_its_bucket(written: dict[str, Any]) -> None:
    script = "\n".join(written["services"]["minio-init"]["command"])
    policy = re.search(r"printf '%s' '(\{.*?\})'", script, re.DOTALL)
    assert policy, script
    statements = yaml.safe_load(policy.group(1))["Statement"]
    resources = {r for s in statements for r in s["Resource"]}
    assert resources == {"arn:aws:s3:::dexlabel-frames", "arn:aws:s3:::dexlabel-frames/*"}
    assert not any(a == "*" or a.startswith("admin:") or a == "s3:*"
                   for s in statements for a in s["Action"])
    bucket = written["x-dexlabel-env"]["DEXLABEL_STORAGE_URL"].split("/")[2]
    assert bucket == "dexlabel-frames"
    assert "mc admin policy attach local dexlabel-frames --user" in script


def test_the_readme_recipe_lists_every_required_secret() -> None:
    required = set(re.findall(r"\$\{(\w+):\?", COMPOSE_FILE.read_text()))
    assert required == set(SECRETS)
    readme = (ROOT / "README.md").read_text()
    section = readme[readme.index("## Scaling out"):readme.index("### Many annotators")]
    recipe = re.search(r"cat > \.env <<END\n(.*?)\nEND", section, re.DOTALL)
    assert recipe, "the README's compose recipe is gone"
    assert required <= {line.split("=", 1)[0] for line in recipe.group(1).splitlines()}
    for name in required:
        assert f"`{name}`" in section, f"the README does not say what {name} is"
