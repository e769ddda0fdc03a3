#!/usr/bin/env bash
# Builds and runs every cargo-fuzz target of volgen for SECONDS each (default 60), then prints
# one row per target: executions, coverage (libFuzzer's `cov`, edges reached), corpus size and
# crashes. Exits non-zero if any target crashed; the crashing inputs are in artifacts/TARGET/.
#
#   fuzz/run.sh [SECONDS]            every target, one after the other
#   JOBS=2 fuzz/run.sh 600           two targets at a time (one core each)
#   TARGETS="render dataset" fuzz/run.sh 60
#
# Works on a fresh machine: installs cargo-fuzz from crates.io if missing, and uses the nightly
# toolchain when rustup has one, else the stable one with RUSTC_BOOTSTRAP=1 (cargo-fuzz needs
# nightly's -Z flags for the sanitizer and coverage instrumentation).
set -euo pipefail
SECONDS_EACH="${1:-60}"
JOBS="${JOBS:-1}"
cd "$(dirname "$0")"

if ! cargo fuzz --version >/dev/null 2>&1; then
  echo "installing cargo-fuzz"
  cargo install cargo-fuzz --locked
fi
if rustup toolchain list 2>/dev/null | grep -q '^nightly'; then
  FUZZ_CMD="cargo +nightly fuzz"
else
  export RUSTC_BOOTSTRAP=1
  FUZZ_CMD="cargo fuzz"
fi

ALL=$(sed -n 's/^name = "\(.*\)"/\1/p' Cargo.toml | grep -v '^volgen[-_]fuzz$')
TARGETS="${TARGETS:-$ALL}"
echo "building: $(echo $TARGETS)"
$FUZZ_CMD build

mkdir -p logs
# LeakSanitizer reports glibc's registration of a thread-local destructor
# (`__cxa_thread_atexit_impl`, 32 bytes per thread, held in the thread's TLS, which LeakSanitizer
# does not scan) as a leak; glibc frees it when the thread exits. Everything else is reported.
export LSAN_OPTIONS="suppressions=$PWD/lsan.supp${LSAN_OPTIONS:+:$LSAN_OPTIONS}"
run_one() {
  local t="$1"
  mkdir -p "corpus/$t" "seeds/$t" "artifacts/$t"
  # New inputs go to corpus/ (not committed); seeds/ holds the committed starting points.
  local started=$SECONDS
  # Only inputs recorded from now on count as this run's crashes (older ones stay as evidence).
  touch "logs/$t.started"
  $FUZZ_CMD run "$t" "corpus/$t" "seeds/$t" -- \
    -max_total_time="$SECONDS_EACH" -rss_limit_mb=2048 -timeout=20 -print_final_stats=1 \
    >"logs/$t.log" 2>&1 || true
  # Wall time including the (usually no-op) build; a crash ends a target early.
  echo $((SECONDS - started)) >"logs/$t.seconds"
}
export -f run_one
export SECONDS_EACH FUZZ_CMD
printf '%s\n' $TARGETS | xargs -P "$JOBS" -I{} bash -c 'run_one "$1"' _ {}

status=0
printf '| target | seconds run | executions | coverage (edges) | corpus | crashes |\n|---|---|---|---|---|---|\n'
for t in $TARGETS; do
  log="logs/$t.log"
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  cov=$(grep -o 'cov: [0-9]*' "$log" | tail -1 | cut -d' ' -f2)
  corp=$(grep -o 'corp: [0-9]*' "$log" | tail -1 | cut -d' ' -f2)
  crashes=$(find "artifacts/$t" -type f -newer "logs/$t.started" \( -name 'crash-*' -o -name 'oom-*' -o -name 'timeout-*' -o -name 'leak-*' \) | wc -l)
  # (Panics the code catches on purpose are printed too; only libFuzzer's summary counts.)
  if grep -q 'ERROR: libFuzzer\|==ERROR: AddressSanitizer\|^SUMMARY: ' "$log"; then
    crashes=$((crashes > 0 ? crashes : 1))
  fi
  [ "$crashes" -gt 0 ] && status=1
  printf '| %s | %s | %s | %s | %s | %s |\n' "$t" "$(cat "logs/$t.seconds" 2>/dev/null || echo ?)" "${execs:-?}" "${cov:-?}" "${corp:-?}" "$crashes"
done
exit $status
