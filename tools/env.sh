#!/usr/bin/env bash
# Creates (once) the project's virtual environment in .venv with Python 3.11 and the packages
# of requirements.txt, from the package registry. Prints the environment's python.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="$root/.venv"
python="$venv/bin/python"
stamp="$venv/.requirements"
if [ ! -x "$python" ]; then
  base=""
  for candidate in python3.11 python3; do
    if command -v "$candidate" >/dev/null && "$candidate" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))'; then
      base="$candidate"; break
    fi
  done
  if [ -z "$base" ]; then
    echo "Python 3.11 is needed (the bpy module exists for 3.11 only)" >&2
    exit 1
  fi
  "$base" -m venv "$venv" >&2
fi
if ! cmp -s "$root/requirements.txt" "$stamp" 2>/dev/null; then
  "$python" -m pip install --quiet --upgrade pip >&2
  "$python" -m pip install --quiet -r "$root/requirements.txt" >&2
  cp "$root/requirements.txt" "$stamp"
fi
echo "$python"
