#!/usr/bin/env bash
# Runs the cargo-fuzz targets one after another, each for a bounded time. Not part of CI.
#
#   fuzz/run.sh                  # every target, 60 s each
#   fuzz/run.sh 300              # every target, 300 s each
#   fuzz/run.sh 300 job_spec     # only the named target(s)
#
# Installs cargo-fuzz into fuzz/.tools on first use. Uses the nightly toolchain when rustup
# has one; otherwise stable with RUSTC_BOOTSTRAP=1 (the sanitizer flags are nightly-only).
# Seed inputs are written into fuzz/corpus/<target>/ on each run; what the fuzzer finds
# worth keeping joins them there. A crash, timeout or out-of-memory input is written to
# fuzz/artifacts/<target>/ and the script goes on to the next target, exiting 1 at the end.
# Extra libFuzzer options can go in FUZZ_ARGS (e.g. FUZZ_ARGS="-seed=1 -max_len=65536").
set -euo pipefail
cd "$(dirname "$0")/.."

seconds=${1:-60}
shift || true
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(scene_loader job_spec tile_validator)

if [ ! -x fuzz/.tools/bin/cargo-fuzz ]; then
    cargo install cargo-fuzz --locked --root fuzz/.tools
fi
fuzz=(fuzz/.tools/bin/cargo-fuzz fuzz)
if rustup toolchain list 2>/dev/null | grep -q '^nightly'; then
    export RUSTUP_TOOLCHAIN=nightly
else
    echo "no nightly toolchain: using stable with RUSTC_BOOTSTRAP=1"
    export RUSTC_BOOTSTRAP=1
fi

# --- seed inputs ---------------------------------------------------------------------

u32le() { printf "\\x$(printf %02x $(($1 & 255)))\\x$(printf %02x $(($1 >> 8 & 255)))\\x$(printf %02x $(($1 >> 16 & 255)))\\x$(printf %02x $(($1 >> 24 & 255)))"; }

# glb JSON BIN_PRINTF_ESCAPES BIN_LENGTH > file: a GLB with a JSON chunk and a BIN chunk.
glb() {
    local json=$1 bin=$2 binlen=$3
    while [ $((${#json} % 4)) -ne 0 ]; do json+=' '; done
    local binpad=$(((4 - binlen % 4) % 4))
    u32le 0x46546C67 # "glTF"
    u32le 2
    u32le $((12 + 8 + ${#json} + 8 + binlen + binpad))
    u32le ${#json}
    u32le 0x4E4F534A # "JSON"
    printf %s "$json"
    u32le $((binlen + binpad))
    u32le 0x004E4942 # "BIN\0"
    printf "$bin"
    head -c "$binpad" /dev/zero
}

seed_scenes() {
    local dir=fuzz/corpus/scene_loader zero='\x00\x00\x00\x00' one='\x00\x00\x80\x3f'
    mkdir -p "$dir"
    # One triangle: positions (0,0,0) (1,0,0) (0,1,0).
    local tri="$zero$zero$zero$one$zero$zero$zero$one$zero"
    local view='"bufferViews":[{"buffer":0,"byteLength":36}],"buffers":[{"byteLength":36}]'
    local pos='{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}'
    glb '{"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[0]}],"nodes":[{"mesh":0}],"meshes":[{"primitives":[{"attributes":{"POSITION":0}}]}],"accessors":['"$pos"'],'"$view"'}' \
        "$tri" 36 >"$dir/seed-triangle.glb"
    # The triangle with indices, a material, a camera, a light and a translation animation
    # (key times 0 and 1; translations (0,0,0) and (1,0,0)).
    local idx='\x00\x00\x01\x00\x02\x00\x00\x00'
    glb '{"asset":{"version":"2.0"},"extensionsUsed":["KHR_lights_punctual"],"extensions":{"KHR_lights_punctual":{"lights":[{"type":"point","intensity":5}]}},"scene":0,"scenes":[{"nodes":[0,1,2]}],"nodes":[{"mesh":0,"name":"Tri"},{"camera":0,"translation":[0,0,3]},{"extensions":{"KHR_lights_punctual":{"light":0}},"translation":[0,2,2]}],"cameras":[{"type":"perspective","name":"Main","perspective":{"yfov":0.8,"znear":0.1}}],"materials":[{"pbrMetallicRoughness":{"baseColorFactor":[1,0.5,0.2,1]}}],"meshes":[{"primitives":[{"attributes":{"POSITION":0},"indices":1,"material":0}]}],"animations":[{"name":"Slide","channels":[{"sampler":0,"target":{"node":0,"path":"translation"}}],"samplers":[{"input":2,"output":3}]}],"accessors":['"$pos"',{"bufferView":1,"componentType":5123,"count":3,"type":"SCALAR"},{"bufferView":2,"componentType":5126,"count":2,"type":"SCALAR","min":[0],"max":[1]},{"bufferView":3,"componentType":5126,"count":2,"type":"VEC3"}],"bufferViews":[{"buffer":0,"byteLength":36},{"buffer":0,"byteOffset":36,"byteLength":6},{"buffer":0,"byteOffset":44,"byteLength":8},{"buffer":0,"byteOffset":52,"byteLength":24}],"buffers":[{"byteLength":76}]}' \
        "$tri$idx$zero$one$zero$zero$zero$one$zero$zero" 76 >"$dir/seed-animated.glb"
    # The glTF sample models beside the checkout, when there: the small GLBs as they are.
    if [ -d ../shared/scenes ]; then
        find ../shared/scenes -name '*.glb' -size -256k -exec cp {} "$dir/" \;
    fi
}

seed_specs() {
    local dir=fuzz/corpus/job_spec d
    d=$(printf '5e%.0s' {1..32})
    mkdir -p "$dir"
    printf '{"scene":"%s"}' "$d" >"$dir/seed-minimal.json"
    printf '{"scene":"%s","name":"shot","frames":{"start":1,"end":48,"step":2},"fps":24,"width":1280,"height":720,"camera":"Main","spp":128,"max_depth":8,"seed":3,"shutter":[-0.25,0.25],"motion_steps":5,"animation":"Walk","tile_size":128,"sample_passes":4,"priority":10,"max_attempts":3,"layers":["beauty","albedo","normal","depth"]}' \
        "$d" >"$dir/seed-full.json"
    printf '{"scene":"%s","camera":1,"animation":"Long","fps":1000,"width":16384,"height":16384,"tile_size":8}' \
        "$d" >"$dir/seed-long.json"
    # 4M tasks: over the task limit, which must refuse it before building any tiles.
    printf '{"scene":"%s","frames":{"start":0,"end":0},"width":16384,"height":16384,"tile_size":8}' \
        "$d" >"$dir/seed-large.json"
}

seed_tiles() {
    local dir=fuzz/corpus/tile_validator
    mkdir -p "$dir"
    # Flag 2: a tile the worker's encoder writes for the task's rectangle (16,8 16x12 in a
    # 40x24 frame), 16 samples; then one with two byte edits and a NaN among the values.
    printf '\x02\x10\x00\x00\x00\x27\x17\x10\x08\x0f\x0b\x00\x00\x00\x00\x3f\x00\x00\x80\x3f' \
        >"$dir/seed-tile.bin"
    printf '\x02\x10\x00\x00\x00\x27\x17\x10\x08\x0f\x0b\x02\x40\x01\xff\x90\x00\x10\x00\x00\xc0\x7f\x00\x00\x80\x3f' \
        >"$dir/seed-tile-edited.bin"
    # The task's tile as raw bytes (flags 0, 16 samples), when a tessera binary is built.
    local bin tmp
    for bin in target/release/tessera target/debug/tessera; do
        [ -x "$bin" ] || continue
        tmp=$(mktemp -d)
        if "$bin" render --region 16,8,16,12 --size 40x24 --spp 1 --out "$tmp/tile.exr" >/dev/null 2>&1; then
            { printf '\x00\x10\x00\x00\x00'; cat "$tmp/tile.exr"; } >"$dir/seed-tile-raw.bin"
        fi
        rm -rf "$tmp"
        break
    done
}

seed_scenes
seed_specs
seed_tiles

# --- runs ----------------------------------------------------------------------------

# Seconds per input before libFuzzer calls it a hang, and memory in MB for the whole
# process. Inputs are at most 256 KiB, so these are out of all proportion.
timeout=10
rss_mb=2048
# The largest single allocation, per target: a scene's decoded images and triangles; a
# plan of a million tiles (16 MB, the default task limit); a 16x12 tile.
malloc_mb() {
    case $1 in
        scene_loader) echo 256 ;;
        job_spec) echo 32 ;;
        *) echo 64 ;;
    esac
}

failed=()
for t in "${targets[@]}"; do
    echo "=== $t: ${seconds} s ==="
    # Long lines cut: on a crash cargo-fuzz prints the whole input as a byte list.
    # shellcheck disable=SC2086
    if ! "${fuzz[@]}" run "$t" "fuzz/corpus/$t" -- \
        -max_total_time="$seconds" -timeout="$timeout" \
        -rss_limit_mb="$rss_mb" -malloc_limit_mb="$(malloc_mb "$t")" \
        -max_len=262144 -print_funcs=0 -print_final_stats=1 ${FUZZ_ARGS:-} 2>&1 |
        cut -c1-400; then
        failed+=("$t")
    fi
done

echo
echo "Crash, timeout and out-of-memory inputs land in $(pwd)/fuzz/artifacts/<target>/;"
echo "replay one with: ${RUSTUP_TOOLCHAIN:+RUSTUP_TOOLCHAIN=nightly }${RUSTC_BOOTSTRAP:+RUSTC_BOOTSTRAP=1 }fuzz/.tools/bin/cargo-fuzz fuzz run <target> fuzz/artifacts/<target>/<file>"
if [ ${#failed[@]} -gt 0 ]; then
    echo "findings in: ${failed[*]}"
    ls -l "${failed[@]/#/fuzz/artifacts/}"
    exit 1
fi
echo "no findings"
