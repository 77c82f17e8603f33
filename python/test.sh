#!/usr/bin/env bash
# Builds and installs the Python package into a virtual environment of its own
# (target/python-venv: pip install ./python, maturin from PyPI as the build backend), then runs its
# tests with pytest. Called by the README's test command; any extra arguments go to pytest.
set -euo pipefail
cd "$(dirname "$0")/.."
venv=target/python-venv
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install -q --upgrade pip
fi
"$venv/bin/pip" install -q numpy pytest trimesh rtree
"$venv/bin/pip" install -q ./python
"$venv/bin/python" -m pytest -q python/tests "$@"
