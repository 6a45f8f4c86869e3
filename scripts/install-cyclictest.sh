#!/usr/bin/env bash
# Installs cyclictest (Debian/Ubuntu package `rt-tests`), the reference that
# `chaosd-bench jitter` measures chaosd's wait strategies against. Without it the jitter
# benchmark still runs and says that the cyclictest rows were skipped.
set -euo pipefail

if command -v cyclictest >/dev/null 2>&1; then
    echo "cyclictest is already installed: $(command -v cyclictest)"
    exit 0
fi
if ! command -v apt-get >/dev/null 2>&1; then
    echo "install-cyclictest: no apt-get here; install rt-tests with your package manager" >&2
    exit 1
fi
sudo=""
if [ "$(id -u)" -ne 0 ]; then
    sudo="sudo"
fi
$sudo apt-get update -qq
DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends rt-tests
echo "installed: $(command -v cyclictest)"
