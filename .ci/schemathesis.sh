#!/usr/bin/env bash
# Checks the served HTTP contract (GET /openapi.yaml) against the debug server with
# schemathesis: the coverage, fuzzing and stateful phases (the stateful one follows the links
# from POST /jobs to the job routes), a fixed seed and a bounded number of examples. Any
# failure fails CI. The server runs on a loopback port with a throwaway data directory, one
# worker and small per-job limits, so the jobs it accepts finish in milliseconds.
# Needs python3 with venv (.ci/run installs it) and the package registry for pip.
set -euo pipefail
cd "$(dirname "$0")/.."

version=4.32.5
seed=${SCHEMATHESIS_SEED:-20261202}
examples=${SCHEMATHESIS_EXAMPLES:-100}
port=${SCHEMATHESIS_PORT:-18473}
venv=target/schemathesis-venv
bin=target/debug/contact-sim

if [ "$("$venv/bin/schemathesis" --version 2>/dev/null)" != "schemathesis, version $version" ]; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install --quiet --disable-pip-version-check "schemathesis==$version"
fi
# Up to date after `cargo test` (a no-op then).
cargo build --locked --bin contact-sim

data=$(mktemp -d)
"$bin" serve --addr "127.0.0.1:$port" --data-dir "$data" --workers 1 \
  --max-nodes 200 --max-steps 32 --submit-rate 0 >"$data/server.log" 2>&1 &
server=$!
cleanup() {
  kill "$server" 2>/dev/null || true
  wait "$server" 2>/dev/null || true
  rm -rf "$data"
}
trap cleanup EXIT

status=0
"$venv/bin/schemathesis" --config-file .ci/schemathesis.toml run \
  "http://127.0.0.1:$port/openapi.yaml" --wait-for-schema 30 \
  --phases coverage,fuzzing,stateful --seed "$seed" --max-examples "$examples" \
  --workers 1 --no-color --report-dir target/schemathesis-report --report junit \
  || status=$?
if grep -q panicked "$data/server.log"; then
  cat "$data/server.log" >&2
  status=1
fi
exit "$status"
