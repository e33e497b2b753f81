#!/usr/bin/env bash
# Checks the served HTTP contract (GET /openapi.yaml) against the debug server with
# schemathesis: every check (`--checks all`: status codes, content types, headers and bodies
# against the contract, schema-valid requests accepted and invalid ones refused, Allow on 405,
# use after delete, ...; the per-route exceptions are in schemathesis.toml), the coverage,
# fuzzing and stateful phases (the stateful one follows the links from POST /jobs to the job
# routes), a fixed seed and a bounded number of examples. Any failure fails CI. The server runs on an ephemeral loopback port with a throwaway data
# directory, one worker and small per-job limits, so the jobs it accepts finish in
# milliseconds.
# Needs python3 with venv (.ci/run installs it) and the package registry for pip.
set -euo pipefail
cd "$(dirname "$0")/.."

version=4.32.5
seed=${SCHEMATHESIS_SEED:-20261202}
examples=${SCHEMATHESIS_EXAMPLES:-100}
venv=target/schemathesis-venv
bin=target/debug/contact-sim

if [ "$("$venv/bin/schemathesis" --version 2>/dev/null)" != "schemathesis, version $version" ]; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install --quiet --disable-pip-version-check "schemathesis==$version"
fi
# Up to date after `cargo test` (a no-op then).
cargo build --locked --bin contact-sim

data=$(mktemp -d)
RUST_LOG=info "$bin" serve --addr 127.0.0.1:0 --data-dir "$data" --workers 1 \
  --max-nodes 200 --max-steps 32 --submit-rate 0 >"$data/server.log" 2>&1 &
server=$!
cleanup() {
  kill "$server" 2>/dev/null || true
  wait "$server" 2>/dev/null || true
  rm -rf "$data"
}
trap cleanup EXIT
# The ephemeral port, from the server's start-up line "listening on http://ADDR".
url=""
for _ in $(seq 300); do
  url=$(grep -o 'listening on http://[^ ]*' "$data/server.log" | head -n1 | cut -d' ' -f3 || true)
  [ -n "$url" ] && break
  kill -0 "$server" 2>/dev/null || break
  sleep 0.1
done
if [ -z "$url" ]; then
  echo "contact-sim serve did not start:" >&2
  cat "$data/server.log" >&2
  exit 1
fi

status=0
"$venv/bin/schemathesis" --config-file .ci/schemathesis.toml run \
  "$url/openapi.yaml" --wait-for-schema 30 \
  --checks all --phases coverage,fuzzing,stateful --seed "$seed" --max-examples "$examples" \
  --workers 1 --no-color --report-dir target/schemathesis-report --report junit \
  || status=$?
if grep -q panicked "$data/server.log"; then
  cat "$data/server.log" >&2
  status=1
fi
exit "$status"
