#!/usr/bin/env bash
# Installs what checks deploy/kubernetes against the Kubernetes and KEDA schemas
# (tests/kubernetes: kubernetes-models, @kubernetes-models/keda, TypeScript and js-yaml from
# the npm registry, at the versions its package-lock.json pins) into
# tests/kubernetes/node_modules. Needs Node.js and npm.
# Exits 0 when the check can run afterwards, 1 (saying why) when it cannot.
set -euo pipefail
cd "$(dirname "$0")/../tests/kubernetes"

if ! command -v node >/dev/null || ! command -v npm >/dev/null; then
    echo "install-kubernetes-check: Node.js and npm are needed (Debian: apt-get install nodejs npm)" >&2
    exit 1
fi
if [ -d node_modules ] && npm ls --omit=dev >/dev/null 2>&1; then
    echo "install-kubernetes-check: installed"
    exit 0
fi
echo "install-kubernetes-check: installing the schema packages from the npm registry ..."
npm ci --no-audit --no-fund --loglevel=error >/dev/null
echo "install-kubernetes-check: installed"
