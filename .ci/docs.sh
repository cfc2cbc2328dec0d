#!/usr/bin/env bash
# CI: the documentation site, built with warnings as errors into site/ (reference pages
# generated first from the scenario checker's rules and the built FMUs).
set -euo pipefail
cd "$(dirname "$0")/.."
[ -x .venv/bin/python ] || python3 -m venv .venv
.venv/bin/pip install -q -c constraints.txt -e '.[docs]'
.venv/bin/python docs/generate.py
.venv/bin/python -m mkdocs build --strict --clean
