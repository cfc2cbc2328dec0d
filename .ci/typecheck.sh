#!/usr/bin/env bash
# Type-check with mypy (pinned in the dev extra). The folders are the packages, so mypy
# reads the checkout as it is. First every package with mypy's defaults (the hints there
# are; unannotated functions are not checked), then the public API strictly (movingbase.run /
# campaign / load_scenario, Result, RunResult, CampaignResult, Records: every function hinted).
set -euo pipefail
cd "$(dirname "$0")/.."
[ -x .venv/bin/mypy ] || { python3 -m venv .venv && .venv/bin/pip install -q -c constraints.txt -e '.[dev]'; }
.venv/bin/mypy --python-version 3.11 --ignore-missing-imports --no-incremental \
    -p plant -p controller -p fmu_src -p scenarios -p studies -p movingbase
.venv/bin/mypy --python-version 3.11 --follow-imports=silent --ignore-missing-imports \
    --disallow-untyped-defs --disallow-incomplete-defs --warn-unused-ignores --no-incremental \
    -m movingbase -m movingbase.api -m scenarios.cosim.records
