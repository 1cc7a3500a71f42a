#!/usr/bin/env bash
# The soak, not part of CI: a short run of every fuzz target, then a farm that renders for
# a long time under random SIGKILLs of workers and the server, random worker stalls and a
# full disk now and then (the server's data folder on a small tmpfs of its own), and
# checks at the end that every frame equals a direct render and no task was leased again
# after it was accepted (tests/tests/soak.rs). Prints the figures RELIABILITY.md records.
#
#   scripts/soak.sh              # 30 minutes of farm, 60 s per fuzz target
#   scripts/soak.sh 600 0        # 10 minutes of farm, no fuzzing
#
# A failure prints TESSERA_SOAK_SEED; set it to repeat the same faults.
set -euo pipefail
cd "$(dirname "$0")/.."

seconds=${1:-1800}
fuzz_seconds=${2:-60}
if [ "$fuzz_seconds" -gt 0 ]; then
    fuzz/run.sh "$fuzz_seconds"
fi
cargo build --release -p cli
TESSERA_SOAK_SECONDS=$seconds cargo test --release -p tests --test soak -- --ignored --nocapture
