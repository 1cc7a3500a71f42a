#!/usr/bin/env bash
# Installs Debian packages for one of the project's install scripts:
#   bash scripts/apt-install.sh NAME PACKAGE...
# NAME prefixes its messages. Uses sudo when not root. Exits 1, saying why, where apt-get
# or the rights to use it are missing or the install fails.
set -euo pipefail
name="$1"
shift

if ! command -v apt-get >/dev/null; then
    echo "$name: no apt-get here; install $* (or their equivalents) with your package manager" >&2
    exit 1
fi
sudo=""
if [ "$(id -u)" != 0 ]; then
    if command -v sudo >/dev/null; then sudo="sudo"; else
        echo "$name: installing $* needs root (or sudo)" >&2
        exit 1
    fi
fi
echo "$name: installing Debian's $* ..."
$sudo apt-get update -qq >/dev/null || true
DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "$@" >/dev/null
