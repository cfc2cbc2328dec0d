#!/usr/bin/env bash
# Optional, not in .ci/run: the FMI 3.0 FMUs under a third FMI 3.0 host (ecos, the second,
# runs in the default suite): fmi-sim, the command-line simulator of the pure-Rust FMI
# importer rust-fmi, built here from crates.io with cargo (pinned version, its own
# Cargo.lock), then tests/hosts/test_fmi3_hosts.py with fmi-sim required, which runs every native
# FMI 3.0 FMU under it and compares with fmpy. The build takes ~25 min on two cores the
# first time; FMI_SIM_ROOT keeps it (default ~/.cache/movingbase/fmi-sim-<version>).
set -euo pipefail
cd "$(dirname "$0")/.."
VERSION=0.7.0
ROOT="${FMI_SIM_ROOT:-$HOME/.cache/movingbase/fmi-sim-$VERSION}"
if [ ! -x "$ROOT/bin/fmi-sim" ]; then
    if ! command -v cargo >/dev/null; then
        echo "fmi3_host.sh: cargo is needed to build fmi-sim $VERSION (Debian: apt-get install cargo)" >&2
        exit 1
    fi
    if ! ls /usr/lib/llvm-*/lib/libclang*.so* >/dev/null 2>&1 && [ -z "${LIBCLANG_PATH:-}" ]; then
        # fmi-sys generates its FMI bindings with bindgen, which needs libclang
        if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
            apt-get install -y -q libclang-dev >/dev/null || { apt-get update -q >/dev/null && apt-get install -y -q libclang-dev >/dev/null; }
        else
            echo "fmi3_host.sh: fmi-sim's build needs libclang (Debian: apt-get install libclang-dev)" >&2
            exit 1
        fi
    fi
    echo "fmi3_host.sh: building fmi-sim $VERSION from crates.io into $ROOT" >&2
    cargo install fmi-sim --version "$VERSION" --locked --root "$ROOT"
fi
if [ ! -x .venv/bin/python ]; then
    python3 -m venv .venv && .venv/bin/pip install -q -e '.[dev]'
fi
MB_FMI_SIM="$ROOT/bin/fmi-sim" MB_REQUIRE_FMI3_HOST=1 .venv/bin/python -m pytest -q tests/hosts/test_fmi3_hosts.py
