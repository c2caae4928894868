#!/usr/bin/env bash
# Every measurement of benchmarks/README.md, one after the other, float32: the same as
# `python -m benchmarks --all` (the benchmarks' one entry point, which this script calls).
# Usage: bash benchmarks/run_all.sh [PYTHON]   (from the repository root; ~25 min on a quiet 2-core machine)
set -euo pipefail
PY=${1:-.venv/bin/python}
export PYTHONPATH=${PYTHONPATH:-$PWD}
exec $PY -m benchmarks --all --python "$PY"
