#!/usr/bin/env bash
# The native FMUs under AddressSanitizer and UndefinedBehaviorSanitizer (issues 18 and 20):
# every native FMU is built as FMI 2.0 and as FMI 3.0, each binary is rebuilt from the FMU's
# own sources/ (what an importer compiles: FMI 2.0, every sources/*.c; FMI 3.0, the files,
# include directories and libraries its sources/buildDescription.xml lists) with
# -fsanitize=address,undefined -fsanitize=float-cast-overflow, and the misuse harness
# (tests/hosts/test_c_host_misuse.py, its native cases: misuse.c on the FMI 2.0 builds, misuse3.c on
# the FMI 3.0 ones), then the random call sequences of tests/hosts/test_c_host_fuzz.py (fuzz.c), run
# on those builds with hosts built with the same sanitizers. Any
# report fails the run (-fno-sanitize-recover=all).
#
# Standalone: .ci/sanitize.sh   (after `pip install -e '.[dev]'`; PYTHON=... picks another
# interpreter, CC=... another compiler). About 3 to 3.5 minutes on 2 shared cores
# (measured with FMI 3.0 added: 2 min 57 s and 3 min 26 s; the harness 56 s of it, 591 cases).
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

from fmu_src import native_build
from fmu_src import python_build as builder

out = pathlib.Path(sys.argv[1])
python = builder.ensure_built(builder.available(), out / "python")
for script, path in python.items():
    fmu = native_build.build_native(path, out / "native")
    fmu3 = native_build.build_native3(fmu, out / "native3")
    for built, folder in ((fmu, "fmus"), (fmu3, "fmus3")):
        with zipfile.ZipFile(built) as z:
            z.extractall(out / folder / built.stem)
    print(f"sanitize: {fmu.stem} built (FMI 2.0 and 3.0)", file=sys.stderr)
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
build3() {   # one FMI 3.0 FMU folder: its binary as its buildDescription.xml says, sanitized
    local dir=$1 id args
    id=$(basename "$dir")
    mapfile -t args < <("$PY" - "$dir/sources" <<'PYTHON'
import pathlib
import sys
import xml.etree.ElementTree as ET

sources = pathlib.Path(sys.argv[1])
config = ET.parse(sources / "buildDescription.xml").getroot().find("BuildConfiguration")
for files in config.iter("SourceFileSet"):
    print(f"-std={files.get('language', 'C99').lower()}")
    print(*(f"-I{sources / d.get('name')}" for d in files.iter("IncludeDirectory")), sep="\n")
    print(*(sources / f.get("name") for f in files.iter("SourceFile")), sep="\n")
print(*(f"-l{lib.get('name')}" for lib in config.iter("Library")), sep="\n")
PYTHON
)
    # shellcheck disable=SC2086
    "$CC" -shared -fPIC -ffp-contract=off -fvisibility=hidden $SAN -I"$HEADERS" "${args[@]}" \
        -o "$dir/binaries/x86_64-linux/$id.so" && echo "sanitize: $id (FMI 3.0) built with sanitizers" >&2
}
export -f build build3
export CC SAN HEADERS PY
printf '%s\0' "$WORK"/fmus/*/ | xargs -0 -n 1 -P "$(nproc)" bash -c 'build "$0"'
printf '%s\0' "$WORK"/fmus3/*/ | xargs -0 -n 1 -P "$(nproc)" bash -c 'build3 "$0"'

export MOVINGBASE_MISUSE_FMUS="$WORK/fmus" MOVINGBASE_MISUSE_FMUS3="$WORK/fmus3" MOVINGBASE_HOST_CFLAGS="$SAN"
export ASAN_OPTIONS="detect_leaks=1:halt_on_error=1" UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
"$PY" -m pytest -q tests/hosts/test_c_host_misuse.py -k "not pythonfmu" -m "slow or not slow" -p no:cacheprovider
# random call sequences (tests/hosts/c_host/fuzz.c) on the same builds, FMI 2.0 and FMI 3.0, the
# slow seeds too: 64 runs of 5,000 calls and 480 of 10,000, 1 min 44 s (the whole script 4 min 11 s)
MOVINGBASE_FUZZ_CALLS=5000 "$PY" -m pytest -q tests/hosts/test_c_host_fuzz.py -m "slow or not slow" -p no:cacheprovider
