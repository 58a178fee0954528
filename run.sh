#!/usr/bin/env bash
# The two set-up commands of README.md:
#   ./run.sh demo [ARGS...]   create/refresh .venv, install pinned deps, run `wearpose demo`
#   ./run.sh test [ARGS...]   same set-up, then run the test suite (pytest)
# Anything else after `./run.sh` is passed to the `wearpose` command in the venv.
set -euo pipefail
cd "$(dirname "$0")"
VENV="${WEARPOSE_VENV:-.venv}"
PY="${PYTHON:-python3}"
if ! "$PY" -c 'import sys; sys.exit(0 if sys.version_info[:2] == (3, 11) else 1)'; then
  echo "wearpose needs Python 3.11 (found: $("$PY" --version 2>&1)); set PYTHON=/path/to/python3.11" >&2
  exit 2
fi
if [ ! -x "$VENV/bin/python" ]; then
  "$PY" -m venv "$VENV"
fi
# Re-install only when the pinned dependencies change (hash of pyproject.toml).
stamp="$VENV/.wearpose-installed-$(sha256sum pyproject.toml | cut -c1-16)"
if [ ! -f "$stamp" ]; then
  "$VENV/bin/python" -m pip install --quiet --upgrade pip
  # torch==2.13.0 first and alone: on the reference machine this takes the local CPU wheel;
  # letting the resolver pick torch through another package could pull a multi-GB CUDA build.
  "$VENV/bin/python" -m pip install --quiet "torch==2.13.0"
  "$VENV/bin/python" -m pip install --quiet -e ".[test]"
  rm -f "$VENV"/.wearpose-installed-*
  touch "$stamp"
fi
cmd="${1:-demo}"
shift || true
case "$cmd" in
  test) exec "$VENV/bin/python" -m pytest "$@" ;;
  *) exec "$VENV/bin/wearpose" "$cmd" "$@" ;;
esac
