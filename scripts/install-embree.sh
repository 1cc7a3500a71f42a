#!/usr/bin/env bash
# Installs native Embree 3 (Debian's libembree-dev) for `tessera bench rays --embree`, the
# BVH comparison; the tracer never uses it. Then build with the benchmark's feature:
#   cargo build --release -p cli --features embree
# Exits 0 when Embree is there afterwards, 1 (saying why) when it could not be installed.
set -euo pipefail

have_embree() {
    ldconfig -p 2>/dev/null | grep -q 'libembree3\.so ' && [ -e /usr/include/embree3/rtcore.h ]
}

if have_embree; then
    echo "install-embree: Embree 3 is installed"
    exit 0
fi
if ! command -v apt-get >/dev/null; then
    echo "install-embree: no apt-get here; install Embree 3 (libembree3 and its headers) with your package manager" >&2
    exit 1
fi
sudo=""
if [ "$(id -u)" != 0 ]; then
    if command -v sudo >/dev/null; then sudo="sudo"; else
        echo "install-embree: installing libembree-dev needs root (or sudo)" >&2
        exit 1
    fi
fi
echo "install-embree: installing Debian's libembree-dev ..."
$sudo apt-get update -qq >/dev/null || true
DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends libembree-dev >/dev/null
have_embree || { echo "install-embree: libembree-dev installed but libembree3.so not found" >&2; exit 1; }
echo "install-embree: Embree 3 is installed"
