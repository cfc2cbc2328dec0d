#!/usr/bin/env bash
# CI, before the test suite: what the other masters need (fmpy.ssp, libcosim, ecos). ecos
# (pip ecospy: dev extra, pinned in constraints.txt) loads only with Debian's libtbb12;
# without it tests/hosts/test_ecos.py (ecos as a third SSP master) and tests/hosts/test_fmi3_hosts.py
# (ecos as the second FMI 3.0 host) skip, so it is installed here and ecos must load.
set -euo pipefail
cd "$(dirname "$0")/.."
if ! ldconfig -p | grep -q 'libtbb\.so\.12'; then
    SUDO=$([ "$(id -u)" -eq 0 ] || echo sudo)
    $SUDO apt-get update -q && $SUDO apt-get install -y -q libtbb12
fi
[ -x .venv/bin/python ] || python3 -m venv .venv
.venv/bin/pip install -q -c constraints.txt -e '.[dev]'
.venv/bin/python -c 'import ecospy; print("ecos", ecospy.EcosLib.version())'   # fails loudly if it cannot load
