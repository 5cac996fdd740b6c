#!/usr/bin/env bash
# A bounded schemathesis run against a real `ffdic serve` on the small mock bench.
#
#   tests/schemathesis/run.sh [BINARY]        (default: target/debug/ffdic)
#
# Creates (or reuses) a venv in target/schemathesis-venv with the pinned requirements, starts the
# daemon on 127.0.0.1:0 with a temporary data folder, runs every check in every phase
# (examples, coverage, fuzzing, stateful) with the settings in schemathesis.toml (fixed seed,
# bounded examples and request timeout), prints a one-line summary and exits non-zero on any
# failure, any error, or a daemon that did not survive the run.
#
# Environment: SCHEMATHESIS_MAX_SECONDS (default 420) is a hard wall-clock limit on the
# schemathesis process; SCHEMATHESIS_REPORT_DIR (default target/schemathesis-report) keeps the
# JSON/NDJSON/JUnit reports and the daemon's log; extra arguments after the binary are passed
# to `schemathesis run` (e.g. `--max-examples 5`, `--include-path /api/v1/stage/moves`).
set -euo pipefail

HERE="$(cd "$(dirname "$0")" && pwd)"
ROOT="$(cd "$HERE/../.." && pwd)"
cd "$ROOT"

VENV="$ROOT/target/schemathesis-venv"   # scripts/test-all.sh makes it ahead: keep the two alike

# --- the venv: made only when missing or when the pinned requirements changed since ---------
bash "$ROOT/scripts/pip-venv.sh" "$VENV" "$HERE/requirements.txt" schemathesis

BIN="${1:-target/debug/ffdic}"
shift || true
[ -x "$BIN" ] || { echo "schemathesis: no daemon binary at $BIN (cargo build --bin ffdic)" >&2; exit 2; }
BIN="$(cd "$(dirname "$BIN")" && pwd)/$(basename "$BIN")"

REPORT_DIR="${SCHEMATHESIS_REPORT_DIR:-$ROOT/target/schemathesis-report}"
MAX_SECONDS="${SCHEMATHESIS_MAX_SECONDS:-420}"

# --- the daemon on the small mock bench ------------------------------------------------------
TMP="$(mktemp -d "${TMPDIR:-/tmp}/ffdic-schemathesis.XXXXXX")"
DAEMON_PID=""
cleanup() {
  if [ -n "$DAEMON_PID" ] && kill -0 "$DAEMON_PID" 2>/dev/null; then
    kill -TERM "$DAEMON_PID" 2>/dev/null || true
    for _ in $(seq 1 60); do kill -0 "$DAEMON_PID" 2>/dev/null || break; sleep 0.25; done
    kill -KILL "$DAEMON_PID" 2>/dev/null || true
  fi
  mkdir -p "$REPORT_DIR"
  cp "$TMP/daemon.stderr" "$REPORT_DIR/daemon.log" 2>/dev/null || true
  rm -rf "$TMP"
}
trap cleanup EXIT
trap 'exit 130' INT TERM

# The same bench as small_config_toml in tests/common/daemon.rs.
cat >"$TMP/ffdic.toml" <<EOF
data_dir = "$TMP/data"
listen = "127.0.0.1:0"
[bench]
scale_px_per_mm = 13.0
[camera]
kind = "mock"
width = 400
height = 320
[stage]
kind = "mock"
speed_mm_s = 25.0
settle_ms = 10
# The sweeps schemathesis sends run on the compute lane while it goes on: small ones only.
[sweeps]
max_tasks = 64
max_sensor_side_px = 256
EOF

NO_COLOR=1 RUST_LOG="${RUST_LOG:-info}" nice -n 5 "$BIN" serve --config "$TMP/ffdic.toml" \
  >"$TMP/daemon.stdout" 2>"$TMP/daemon.stderr" &
DAEMON_PID=$!

ADDR=""
for _ in $(seq 1 300); do
  line="$(head -n 1 "$TMP/daemon.stdout" 2>/dev/null || true)"
  case "$line" in
    "listening on http://"*) ADDR="${line#listening on http://}"; break ;;
  esac
  kill -0 "$DAEMON_PID" 2>/dev/null || break
  sleep 0.1
done
if [ -z "$ADDR" ]; then
  echo "schemathesis: the daemon did not start; its log:" >&2
  tail -n 30 "$TMP/daemon.stderr" >&2 || true
  exit 2
fi

SPEC_URL="http://$ADDR/api/v1/openapi.json"
curl -fsS "$SPEC_URL" -o "$TMP/openapi.json"
# The document's paths carry the /api/v1 prefix themselves (no `servers`): the base URL is then
# the bare origin. Should the prefix move into `servers` or out of the paths, follow it.
BASE_URL="$("$VENV/bin/python" - "$TMP/openapi.json" "http://$ADDR" <<'PY'
import json, sys
spec = json.load(open(sys.argv[1]))
origin = sys.argv[2]
paths = list(spec.get("paths", {}))
if paths and all(p.startswith("/api/v1/") for p in paths):
    print(origin)
else:
    servers = spec.get("servers") or []
    url = servers[0]["url"] if servers else "/api/v1"
    print(url.rstrip("/") if url.startswith("http") else origin + "/" + url.strip("/"))
PY
)"
echo "schemathesis: daemon $ADDR (pid $DAEMON_PID), schema $SPEC_URL, base URL $BASE_URL"

# --- the run ---------------------------------------------------------------------------------
mkdir -p "$REPORT_DIR"
rm -f "$REPORT_DIR"/report.json "$REPORT_DIR"/events.ndjson "$REPORT_DIR"/junit.xml
set +e
NO_COLOR=1 timeout --signal=INT --kill-after=15 "$MAX_SECONDS" \
  nice -n 5 "$VENV/bin/schemathesis" --config-file "$HERE/schemathesis.toml" run "$SPEC_URL" \
  --url "$BASE_URL" \
  --report json,ndjson,junit \
  --report-json-path "$REPORT_DIR/report.json" \
  --report-ndjson-path "$REPORT_DIR/events.ndjson" \
  --report-junit-path "$REPORT_DIR/junit.xml" \
  "$@"
rc=$?
set -e

daemon_alive=1
kill -0 "$DAEMON_PID" 2>/dev/null || daemon_alive=0
if [ "$rc" = 124 ] || [ "$rc" = 130 ]; then
  echo "schemathesis: stopped after the ${MAX_SECONDS} s wall-clock limit" >&2
fi

# --- the summary -----------------------------------------------------------------------------
"$VENV/bin/python" - "$REPORT_DIR/report.json" "$daemon_alive" <<'PY' || true
import json, sys
try:
    r = json.load(open(sys.argv[1]))
except (OSError, ValueError):
    print("schemathesis summary: no report (the run did not finish)")
    sys.exit(0)
ops, cases = r.get("operations") or {}, r.get("test_cases") or {}
failures = r.get("failures") or []
errors = r.get("errors") or []
phases = ", ".join(f"{k} {v['status']}" for k, v in (r.get("phases") or {}).items())
print(
    "schemathesis summary: "
    f"{ops.get('tested', 0)}/{ops.get('selected', ops.get('total', 0))} operations covered, "
    f"{cases.get('generated', 0)} test cases, "
    f"{cases.get('unique_failures', 0)} failures ({len(failures)} kinds, "
    f"{cases.get('with_failures', 0)} cases with failures), "
    f"{sum(e.get('count', 0) for e in errors)} errors, "
    f"{r.get('running_time', 0):.0f} s, seed {r.get('seed')}; phases: {phases}; "
    f"daemon {'alive' if sys.argv[2] == '1' else 'DEAD'} at the end"
)
for f in failures:
    print(f"  failure: {f['title']} ({f['code']}) x{f['count']}: {', '.join(f['operations'][:6])}"
          + (" ..." if len(f["operations"]) > 6 else ""))
for e in errors:
    print(f"  error: {e['title']} x{e['count']}")
PY

if [ "$daemon_alive" != 1 ]; then
  echo "schemathesis: the daemon died during the run; the end of its log:" >&2
  tail -n 30 "$TMP/daemon.stderr" >&2 || true
  exit 1
fi
exit "$rc"
