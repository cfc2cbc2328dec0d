#!/usr/bin/env bash
# The native FMUs under AddressSanitizer and UndefinedBehaviorSanitizer (issue 18): every
# native FMU is built, its binary is rebuilt from the FMU's own sources/ (what an importer
# compiles) with -fsanitize=address,undefined -fsanitize=float-cast-overflow, and the misuse
# harness (tests/test_fmu_misuse.py, its native cases) runs on those builds with a host
# built with the same sanitizers. Any report fails the run (-fno-sanitize-recover=all).
#
# Standalone: .ci/sanitize.sh   (after `pip install -e '.[dev]'`; PYTHON=... picks another
# interpreter, CC=... another compiler). About 4 minutes on 2 shared cores (the harness: 20 s).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-.venv/bin/python}
CC=${CC:-cc}
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
SAN="-fsanitize=address,undefined -fsanitize=float-cast-overflow -fno-sanitize-recover=all -fno-omit-frame-pointer -g -O1"

echo "sanitize: building the FMUs" >&2
"$PY" - "$WORK" <<'PYTHON'
import pathlib
import sys
import zipfile

from movingbase.fmu_src import builder, native_build

out = pathlib.Path(sys.argv[1])
python = builder.ensure_built(builder.available(), out / "python")
for script, path in python.items():
    fmu = native_build.build_native(path, out / "native")
    with zipfile.ZipFile(fmu) as z:
        z.extractall(out / "fmus" / fmu.stem)
    print(f"sanitize: {fmu.stem} built", file=sys.stderr)
PYTHON

HEADERS=$("$PY" -c 'import fmpy, pathlib; print(pathlib.Path(fmpy.__file__).parent / "c-code")')
echo "sanitize: every binary again from its sources/ with $SAN" >&2
build() {   # one FMU folder: its binary from its sources/, sanitized
    local dir=$1 id
    id=$(basename "$dir")
    # shellcheck disable=SC2086
    "$CC" -shared -fPIC -std=c99 -ffp-contract=off -fvisibility=hidden $SAN -I"$HEADERS" -I"$dir/sources" \
        "$dir"/sources/*.c -o "$dir/binaries/linux64/$id.so" -lm && echo "sanitize: $id built with sanitizers" >&2
}
export -f build
export CC SAN HEADERS
printf '%s\0' "$WORK"/fmus/*/ | xargs -0 -n 1 -P "$(nproc)" bash -c 'build "$0"'

export MOVINGBASE_MISUSE_FMUS="$WORK/fmus" MOVINGBASE_HOST_CFLAGS="$SAN"
export ASAN_OPTIONS="detect_leaks=1:halt_on_error=1" UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
"$PY" -m pytest -q tests/test_fmu_misuse.py -k "not pythonfmu" -m "slow or not slow" -p no:cacheprovider
