#!/usr/bin/env bash
# OCIO 2.1 (VFX Reference Platform CY2022; Debian 12's opencolorio-tools) for the test
# that loads the bundled and exported configs with its ociocheck / ocioconvert
# (tests/colour/test_ocio_versions.py). Best effort: where apt is not ours to use, the
# test says so (and fails in CI, where it must run).
set -u
if command -v ociocheck >/dev/null 2>&1 && [ -x /usr/bin/ociocheck ]; then
    exit 0
fi
if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    export DEBIAN_FRONTEND=noninteractive
    apt-get install -y -q opencolorio-tools >/dev/null 2>&1 || \
        { apt-get update -q >/dev/null 2>&1 && apt-get install -y -q opencolorio-tools >/dev/null 2>&1; } || \
        echo "ci: could not install opencolorio-tools (OCIO 2.1's ociocheck)"
fi
exit 0
