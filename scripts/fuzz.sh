#!/usr/bin/env bash
# Runs the libFuzzer targets of fuzz/ (issue 11) with cargo-fuzz on the nightly toolchain,
# each for SECONDS, one after the other (nice'd), starting from the seeds of
# bevt_tests::fuzz plus what earlier runs kept in fuzz/corpus/<target>/ (git-ignored).
# Crashes land in fuzz/artifacts/<target>/; once fixed, copy each to
# fuzz/regressions/<target>/ so `cargo test` replays it.
#
#   scripts/fuzz.sh [SECONDS] [TARGET...]     (default 300 s, every target)
#
# Needs `cargo install cargo-fuzz` and a nightly toolchain (`rustup toolchain install
# nightly`); the stable, bounded run of the same bodies is
# `cargo test -p bevt_tests --test integration fuzz`.
set -euo pipefail
cd "$(dirname "$0")/.."
secs=${1:-300}
shift || true
all=(image_raw image_compressed cdr_messages node_requests param_requests ros_args params_file tracker_config dataset_manifest annotation bag_reader)
if [ $# -eq 0 ]; then targets=("${all[@]}"); else targets=("$@"); fi
# Seeds, written by the stable harness.
BEVT_FUZZ_SEED_DIR="$PWD/fuzz/corpus" BEVT_FUZZ_ITERS=0 \
  cargo test -q -p bevt_tests --test integration fuzz:: >/dev/null
for t in "${targets[@]}"; do
  mkdir -p "fuzz/corpus/$t" "fuzz/artifacts/$t"
  echo "== $t ($secs s)"
  # No sanitizer (the project forbids unsafe code; panics, aborts, timeouts and memory
  # are what is looked for) and debug assertions on (integer overflow is a finding).
  # -rss_limit_mb: an input that makes the body allocate past it is a finding.
  # bag_reader runs the bag reader with its real 1 GiB record limit: a lower RSS limit
  # makes an allocation from a declared (untrusted) length a finding.
  rss=2048; [ "$t" = bag_reader ] && rss=512
  nice -n 10 cargo +nightly fuzz run --fuzz-dir fuzz -s none -a "$t" "fuzz/corpus/$t" -- \
    -max_total_time="$secs" -rss_limit_mb=$rss -max_len=8192 -timeout=10 \
    -artifact_prefix="fuzz/artifacts/$t/" -print_final_stats=1 > "fuzz/artifacts/$t/last-run.log" 2>&1 || echo "$t: libFuzzer stopped on a finding (see fuzz/artifacts/$t/)"
  grep -E "^(stat::number_of_executed_units|stat::peak_rss_mb|#[0-9]+ *DONE)|ERROR|SUMMARY" "fuzz/artifacts/$t/last-run.log" || true
done
