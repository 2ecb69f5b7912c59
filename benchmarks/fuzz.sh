#!/usr/bin/env bash
# schemathesis over the live OpenAPI as an authenticated user (issue 9; each role, issue 21): a
# fresh service on a temporary SQLite file, a user "fuzz" with role ROLE (default Expert),
# SECONDS of fuzzing (default 200).
# Prints schemathesis's summary, then the service's answers by status; the last line is
# `role=<ROLE> schemathesis_exit=<0: no failure> cases=<generated> server_errors=<5xx in the access log>`.
#   bash benchmarks/fuzz.sh [SECONDS] [PORT] [ROLE]
set -euo pipefail
cd "$(dirname "$0")/.."
SECONDS_BUDGET=${1:-200}
PORT=${2:-8791}
ROLE=${3:-Expert}
TMP=$(mktemp -d)
export PYTHONPATH=$PWD PENDANT_DB_URL="sqlite:///$TMP/fuzz.db"
export PENDANT_ADMIN_TOKEN="pdt_fuzz-$(python3 -c 'import secrets; print(secrets.token_urlsafe(24))')"
python3 -m server.cli users add fuzz --role "$ROLE" > /dev/null
TOKEN=$(python3 -m server.cli tokens create fuzz --days 1 2> /dev/null)
python3 -m server.cli serve --port "$PORT" > "$TMP/access.log" 2> "$TMP/serve.err" &
SERVER=$!
trap 'kill $SERVER 2> /dev/null; wait $SERVER 2> /dev/null; rm -rf "$TMP"' EXIT
until curl -s -o /dev/null "http://127.0.0.1:$PORT/openapi.json"; do
  kill -0 $SERVER 2> /dev/null || { cat "$TMP/serve.err" >&2; exit 2; }  # serve did not start
  sleep 1
done
set +e
schemathesis run "http://127.0.0.1:$PORT/openapi.json" --checks not_a_server_error \
  -H "Authorization: Bearer $TOKEN" --max-time "$SECONDS_BUDGET" --continue-on-failure \
  --seed 9 -w 1 > "$TMP/st.out" 2>&1
rc=$?
set -e
sed -n '/SUMMARY/,$p' "$TMP/st.out"
echo "answers by status:"
grep -o '" [0-9][0-9][0-9]' "$TMP/access.log" | sort | uniq -c
cases=$(grep -o '[0-9]* generated' "$TMP/st.out" | tail -1 | cut -d' ' -f1)
echo "role=$ROLE schemathesis_exit=$rc cases=${cases:-0} server_errors=$(grep -c '" 5[0-9][0-9]' "$TMP/access.log" || true)"
