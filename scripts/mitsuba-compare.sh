#!/usr/bin/env bash
# The tracer speed issue's comparison, side by side on this machine: the measured Cornell
# box (256x256, max depth 8, all cores) in Tessera and in Mitsuba 3 (`scripts/
# mitsuba_cornell.py`: its LLVM variant, which traces 8-wide SIMD packets through Embree,
# and its scalar one), in turn, ROUNDS times, at 16 and 256 spp. Prints camera paths/s
# per run, and at 16 spp each renderer's MSE against its own 1024-spp reference.
#
#   bash scripts/mitsuba-compare.sh [ROUNDS]
#
# Installs Mitsuba 3.9.1 into target/mitsuba (a Python virtual environment) and Debian's
# libllvm19 for its JIT (LLVM 15 and older cannot compile its kernels). A benchmark, not a
# test: nothing in the test suite needs it.
set -euo pipefail
cd "$(dirname "$0")/.."
rounds=${1:-3}
venv=target/mitsuba

find_llvm() { find /usr/lib -name 'libLLVM.so.19*' 2>/dev/null | head -n 1; }
if [[ -z $(find_llvm) ]]; then
  bash scripts/apt-install.sh mitsuba-compare libllvm19
fi
llvm=$(find_llvm)
[[ -n $llvm ]] || { echo "mitsuba-compare: libllvm19 installed but libLLVM.so.19 not found" >&2; exit 1; }
if ! "$venv/bin/python" -c 'import mitsuba' 2>/dev/null; then
  echo "mitsuba-compare: installing Mitsuba 3.9.1 into $venv ..."
  python3 -m venv "$venv"
  "$venv/bin/pip" install -q mitsuba==3.9.1
fi
cargo build --release -q -p cli
cargo build --release -q -p tracer --example cornell_profile

mitsuba() { DRJIT_LIBLLVM_PATH="$llvm" "$venv/bin/python" scripts/mitsuba_cornell.py "$@"; }
for round in $(seq "$rounds"); do
  echo "## round $round of $rounds"
  echo -n "tessera: "
  target/release/tessera bench cornell 2>/dev/null | grep 'camera paths/s'
  mitsuba 16 5 --mse llvm_ad_rgb scalar_rgb
  echo -n "tessera 256 spp: "
  target/release/examples/cornell_profile 256
  mitsuba 256 2 llvm_ad_rgb
done
