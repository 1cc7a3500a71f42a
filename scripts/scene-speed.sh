#!/usr/bin/env bash
# Every scene's render speed under two builds of tessera, side by side on this machine:
# the shared sample models (../shared/scenes), the built-in animated demo with a 180°
# shutter, and a skinned figure with motion blur. Renders alternate between the builds,
# each scene twice per build, and the faster of the two counts (this machine class is
# noisy). Prints a markdown table of M samples/s and the ratio.
#
#   scripts/scene-speed.sh BASE_TESSERA NEW_TESSERA [SIZE] [SPP]
#
# A base build of an older commit: git worktree add /tmp/base COMMIT &&
# cargo build --release -p cli --manifest-path /tmp/base/Cargo.toml
set -euo pipefail
base=${1:?usage: scene-speed.sh BASE_TESSERA NEW_TESSERA [SIZE] [SPP]}
new=${2:?usage: scene-speed.sh BASE_TESSERA NEW_TESSERA [SIZE] [SPP]}
size=${3:-256x256}
spp=${4:-32}
scenes_dir="$(cd "$(dirname "$0")/.." && pwd)/../shared/scenes"
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT

# name|scene file (none: the built-in demo)|further options
blur="--shutter -0.25,0.25"
cases=("demo, 180° shutter||--frame 20 $blur")
if [[ -d $scenes_dir ]]; then
  cases+=("RiggedFigure, 180° shutter|$scenes_dir/RiggedFigure/RiggedFigure.glb|--frame 12 $blur")
  for dir in "$scenes_dir"/*/; do
    file=$(ls "$dir"*.glb "$dir"*.gltf 2>/dev/null | head -n 1 || true)
    if [[ -n $file ]]; then cases+=("$(basename "$dir")|$file|"); fi
  done
else
  echo "note: $scenes_dir not found: the demo only" >&2
fi

# Prints the M samples/s that `tessera render` reports, or "failed".
rate() {
  local bin=$1
  shift
  local line
  if line=$("$bin" render "$@" --size "$size" --spp "$spp" --out "$out/frame.exr" 2>&1 |
    grep -o '[0-9.]* M samples/s'); then
    echo "${line%% *}"
  else
    echo failed
  fi
}

best() { printf '%s\n' "$@" | grep -v failed | sort -g | tail -n 1; }

echo "| scene | base (M samples/s) | new (M samples/s) | new / base |"
echo "|---|---:|---:|---:|"
for case in "${cases[@]}"; do
  IFS='|' read -r name file options <<<"$case"
  read -r -a args <<<"$options"
  if [[ -n $file ]]; then args=("$file" "${args[@]}"); fi
  b1=$(rate "$base" "${args[@]}"); n1=$(rate "$new" "${args[@]}")
  b2=$(rate "$base" "${args[@]}"); n2=$(rate "$new" "${args[@]}")
  b=$(best "$b1" "$b2"); n=$(best "$n1" "$n2")
  if [[ -z $b || -z $n ]]; then
    echo "| $name | ${b:-failed} | ${n:-failed} | |"
  else
    echo "| $name | $b | $n | $(awk -v n="$n" -v b="$b" 'BEGIN { printf "%.2f", n / b }') |"
  fi
done
