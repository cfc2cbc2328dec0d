#!/usr/bin/env bash
# CI: the exported SSP under the other masters (fmpy.ssp, libcosim, ecos) and every FMU
# under a plain fmpy.simulate_fmu. ecos (pip ecospy: dev extra, pinned in constraints.txt) loads only
# with Debian's libtbb12; without it tests/test_ecos.py skips, so install it here.
set -euo pipefail
cd "$(dirname "$0")/.."
if ! ldconfig -p | grep -q 'libtbb\.so\.12'; then
    SUDO=$([ "$(id -u)" -eq 0 ] || echo sudo)
    $SUDO apt-get update -q && $SUDO apt-get install -y -q libtbb12
fi
[ -x .venv/bin/python ] || python3 -m venv .venv
.venv/bin/pip install -q -c constraints.txt -e '.[dev]'
.venv/bin/python -c 'import ecospy; print("ecos", ecospy.EcosLib.version())'   # fails loudly if it cannot load
.venv/bin/python -m pytest -q -rs tests/test_ecos.py tests/test_libcosim.py tests/test_ssp.py tests/test_defaults.py
