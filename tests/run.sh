#!/usr/bin/env bash
# Installs what the tests need (a virtualenv with the project and its test extras; PostgreSQL
# and Redis started if they are installed but down), checks lint and types (tests/lint.sh: ruff
# and strict mypy; any finding stops here) and runs the whole suite.
# With DEXLABEL_BENCH_SMOKE=1 (CI), the benchmarks' smoke run (bench/smoke.py) runs beside the
# suite, on the cores the suite leaves idle while it waits on its servers and browsers; the
# run fails if either does, and the smoke run's report follows the suite's.
# Usage: bash tests/run.sh [pytest args...]
set -euo pipefail
cd "$(dirname "$0")/.."

PY=${PYTHON:-python3}
VENV=${DEXLABEL_VENV:-.venv}
if [ ! -x "$VENV/bin/python" ]; then
  "$PY" -m venv "$VENV"
fi
"$VENV/bin/python" -m pip install --quiet --upgrade pip
"$VENV/bin/python" -m pip install --quiet -e '.[test]'
DEXLABEL_VENV="$VENV" bash tests/lint.sh

start_services() {
  if command -v pg_isready >/dev/null && ! pg_isready -q -h 127.0.0.1 -p 5432; then
    if command -v pg_ctlcluster >/dev/null && [ -d /etc/postgresql ]; then
      echo "starting PostgreSQL"
      pg_ctlcluster --skip-systemctl-redirect "$(ls /etc/postgresql | head -n1)" main start || true
    fi
  fi
  if command -v redis-cli >/dev/null && ! redis-cli -h 127.0.0.1 -p 6379 ping >/dev/null 2>&1; then
    if command -v redis-server >/dev/null; then
      echo "starting Redis"
      mkdir -p /var/lib/redis /var/log/redis 2>/dev/null || true
      redis-server --daemonize yes --bind 127.0.0.1 --port 6379 --save "" --appendonly no \
        --dir /var/lib/redis --logfile /var/log/redis/ci.log || true
    fi
  fi
  for _ in $(seq 1 30); do
    pg_ok=1; redis_ok=1
    command -v pg_isready >/dev/null && { pg_isready -q -h 127.0.0.1 -p 5432 || pg_ok=0; }
    command -v redis-cli >/dev/null && { redis-cli -h 127.0.0.1 -p 6379 ping >/dev/null 2>&1 || redis_ok=0; }
    [ "$pg_ok" = 1 ] && [ "$redis_ok" = 1 ] && return 0
    sleep 1
  done
}
start_services

# Browser tests drive Debian's Chromium (a test tool's own browser download is not used).
if [ -z "${DEXLABEL_CHROMIUM:-}" ] && ! command -v chromium >/dev/null; then
  if command -v apt-get >/dev/null && [ "$(id -u)" = 0 ]; then
    echo "installing Debian's chromium for the browser tests"
    apt-get update -qq >/dev/null && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null
  fi
fi

# docker-compose.yml is validated by Debian's docker-compose (tests/deploy; nothing is pulled).
if ! command -v docker-compose >/dev/null; then
  if command -v apt-get >/dev/null && [ "$(id -u)" = 0 ]; then
    echo "installing Debian's docker-compose for the compose file's check"
    apt-get update -qq >/dev/null \
      && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq docker-compose >/dev/null
  fi
fi

# The page's pure core and its golden vectors, in Node's own test runner.
if command -v node >/dev/null; then
  node --test tests/js/
elif [ "${CI:-}" = "true" ]; then
  echo "node is required for the JavaScript tests" >&2
  exit 1
fi

# In CI a missing PostgreSQL or Redis is a failure, not a skip.
if [ "${CI:-}" = "true" ]; then
  export DEXLABEL_TEST_REQUIRE_SERVICES=1
fi
if [ "${DEXLABEL_BENCH_SMOKE:-}" != "1" ]; then
  exec "$VENV/bin/python" -m pytest "$@"
fi
smoke_log=$(mktemp "${TMPDIR:-/tmp}/dexlabel-smoke.XXXXXX")
echo "bench smoke run beside the suite: python bench/smoke.py (report after the suite)"
DEXLABEL_VENV="$VENV" "$VENV/bin/python" bench/smoke.py > "$smoke_log" 2>&1 &
smoke_pid=$!
tests_status=0
"$VENV/bin/python" -m pytest "$@" || tests_status=$?
smoke_status=0
wait "$smoke_pid" || smoke_status=$?
echo "bench smoke run (exit $smoke_status):"
cat "$smoke_log"
rm -f "$smoke_log"
if [ "$tests_status" != 0 ]; then
  exit "$tests_status"
fi
exit "$smoke_status"
