#!/usr/bin/env bash
# Runs every test: the unit tests (in the sanitizer build unless CS_UNIT_BIN says otherwise)
# and every integration script tests/it/*.sh (release and sanitizer binaries). Each prints "PASS name" / "FAIL name" lines;
# this script totals them and ends with the line "N passed, N failed".
set -u
cd "$(dirname "$0")/.."
unit=${CS_UNIT_BIN:-build/san/bin/cs_unit_tests}
log=$(mktemp)
trap 'rm -f "$log"' EXIT

echo "== unit tests ($unit)"
if [ -x "$unit" ]; then
  ulog=$(mktemp)
  ASAN_OPTIONS=detect_leaks=1 "$unit" ${CS_UNIT_ARGS:-} 2>&1 | tee "$ulog"
  rc=${PIPESTATUS[0]}
  cat "$ulog" >> "$log"
  # A sanitizer report ends the runner with exit 1 (as failed tests do) before the test that
  # made it prints its FAIL line and before the tests after it run: without its last line
  # "unit: N passed, N failed" the run is a failure, whatever the exit code (session 44: a
  # use-after-free in one test dropped 80 tests from the count and the total stayed green).
  if [ "$rc" -gt 1 ]; then
    echo "FAIL unit-runner (exit $rc: crashed or sanitizer report)" | tee -a "$log"
  elif ! grep -Eq '^unit: [0-9]+ passed, [0-9]+ failed$' "$ulog"; then
    echo "FAIL unit-runner (exit $rc before its last line: crashed or sanitizer report; see above)" | tee -a "$log"
  elif [ "$rc" -ne 0 ] && ! grep -q '^FAIL ' "$ulog"; then
    echo "FAIL unit-runner (exit $rc with no FAIL line)" | tee -a "$log"
  fi
  rm -f "$ulog"
else
  echo "FAIL unit-runner (no $unit)" | tee -a "$log"
fi

# Integration scripts run twice: against the release binaries, then against the ASan/UBSan
# build (lines prefixed "san:"), so the daemon's and clients' bus paths run under the
# sanitizers too. CS_IT_BUILDS overrides the list of binary folders.
for bin in ${CS_IT_BUILDS:-build/bin build/san/bin}; do
  tag=""; [ "$bin" = build/bin ] || tag="san:"
  for t in tests/it/*.sh; do
    [ -e "$t" ] || continue
    echo "== $t ($bin)"
    one=$(mktemp)
    CS_IT_BIN="$PWD/$bin" timeout 600 bash "$t" 2>&1 | sed -e "s/^PASS /PASS $tag/" -e "s/^FAIL /FAIL $tag/" -e "s/^SKIP /SKIP $tag/" | tee "$one"
    rc=${PIPESTATUS[0]}
    cat "$one" >> "$log"
    if [ "$rc" -ne 0 ] && ! grep -q '^FAIL ' "$one"; then
      echo "FAIL $tag$(basename "$t" .sh) (exit $rc with no FAIL line)" | tee -a "$log"
    fi
    rm -f "$one"
  done
done

p=$(grep -c '^PASS ' "$log")
f=$(grep -c '^FAIL ' "$log")
echo
grep '^SKIP ' "$log" | sed 's/^/  /'   # a test that cannot run yet says why (never counted as passed)
grep '^FAIL ' "$log" | sed 's/^/  /'
echo "$p passed, $f failed"
[ "$f" -eq 0 ] && [ "$p" -gt 0 ]
