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
bash "$(dirname "$0")/apt-install.sh" install-embree libembree-dev
have_embree || { echo "install-embree: libembree-dev installed but libembree3.so not found" >&2; exit 1; }
echo "install-embree: Embree 3 is installed"
