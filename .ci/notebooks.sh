#!/usr/bin/env bash
# Execute the example notebooks (examples/*.ipynb) so that they cannot rot: every cell
# must run without an error on the installed kit (the notebooks extra pins nbclient,
# nbformat, ipykernel and pandas).
set -euo pipefail
cd "$(dirname "$0")/.."
[ -x .venv/bin/python ] || python3 -m venv .venv
.venv/bin/pip install -q -c constraints.txt -e '.[notebooks]'
for notebook in examples/*.ipynb; do
    echo "executing $notebook"
    .venv/bin/python - "$notebook" <<'PY'
import sys
import nbformat
from nbclient import NotebookClient

path = sys.argv[1]
notebook = nbformat.read(path, as_version=4)
NotebookClient(notebook, timeout=600, kernel_name="python3", resources={"metadata": {"path": "examples"}}).execute()
print(f"{path}: {len(notebook.cells)} cells ran")
PY
done
