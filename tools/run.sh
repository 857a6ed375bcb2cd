#!/usr/bin/env bash
# The main job: sets up .venv if needed, then runs the headless command line
# (python -m addon: build a scene, solve, save the .blend, render a PNG preview).
# Paths on the command line are the caller's: it runs from the caller's directory.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
python="$(bash "$root/tools/env.sh")"
PYTHONPATH="$root${PYTHONPATH:+:$PYTHONPATH}" exec "$python" -m addon "$@"
