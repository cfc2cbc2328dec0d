#!/usr/bin/env bash
# Type-check the public API (movingbase.run / campaign / load_scenario, Result, RunResult,
# CampaignResult, Records) with mypy, pinned in the dev extra. mypy cannot follow the
# editable install's package-dir mapping, so it reads a mirror of the installed layout
# (movingbase/ with plant, controller, fmu_src and scenarios linked in); the modules the
# API imports are followed silently (their own hints are not yet checked).
set -euo pipefail
cd "$(dirname "$0")/.."
[ -x .venv/bin/mypy ] || { python3 -m venv .venv && .venv/bin/pip install -q -c constraints.txt -e '.[dev]'; }
mirror=$(mktemp -d)
trap 'rm -rf "$mirror"' EXIT
mkdir "$mirror/movingbase"
ln -s "$PWD/movingbase/__init__.py" "$PWD/movingbase/__main__.py" "$mirror/movingbase/"
for folder in plant controller fmu_src scenarios; do ln -s "$PWD/$folder" "$mirror/movingbase/$folder"; done
cd "$mirror"
"$OLDPWD/.venv/bin/mypy" --python-version 3.11 --follow-imports=silent --ignore-missing-imports \
    --disallow-untyped-defs --disallow-incomplete-defs --warn-unused-ignores --no-incremental \
    -m movingbase -m movingbase.scenarios.api -m movingbase.scenarios.records
