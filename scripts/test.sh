#!/usr/bin/env bash
# The whole test suite, as CI runs it (.ci/run calls this). First installs the optional
# parts that some tests need, where this machine allows it: Embree 3, for the BVH
# comparison of `tessera bench rays --embree`, Intel Open Image Denoise and FFmpeg
# (`tessera install oidn|ffmpeg`, into the user's data folder), for the denoising and
# video tests, Slurm and MUNGE (Debian's packages), for the test that runs a one-node
# Slurm cluster, and the npm packages that check deploy/kubernetes against the Kubernetes
# and KEDA schemas. Then it runs `cargo test --workspace` with the cargo features those parts
# enable. Where a part cannot be installed, it says so loudly and its tests report
# themselves skipped. The fuzz targets (a workspace of their own, run by fuzz/run.sh with
# nightly) are type-checked against today's types first, with their lock file as
# committed. Arguments go to `cargo test`.
set -euo pipefail
cd "$(dirname "$0")/.."

echo "=== the fuzz targets still build against the workspace's types ==="
cargo check --manifest-path fuzz/Cargo.toml --locked --target-dir target/fuzz-check

features=()
if bash scripts/install-embree.sh; then
    features+=(cli/embree)
else
    echo "=== WARNING: Embree 3 is not installed: the Embree comparison's tests will be skipped ===" >&2
fi

echo "=== Open Image Denoise and FFmpeg, for the denoising and video tests ==="
for part in oidn ffmpeg; do
    if ! cargo run -p cli --quiet -- install "$part"; then
        echo "=== WARNING: $part could not be installed: its tests will be skipped ===" >&2
    fi
done

echo "=== Slurm, and the Kubernetes schema check, for the cluster engine tests ==="
bash scripts/install-slurm.sh ||
    echo "=== WARNING: Slurm could not be installed: the Slurm test will be skipped ===" >&2
bash scripts/install-kubernetes-check.sh ||
    echo "=== WARNING: the Kubernetes schema check could not be installed: it will be skipped ===" >&2

if [ ${#features[@]} -gt 0 ]; then
    exec cargo test --workspace --features "$(IFS=,; echo "${features[*]}")" "$@"
fi
exec cargo test --workspace "$@"
