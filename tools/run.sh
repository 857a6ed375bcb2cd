#!/usr/bin/env bash
# The main job: sets up .venv if needed, then runs the headless command line
# (python -m addon: build a scene, solve, save the .blend, render a PNG preview).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
python="$(bash "$root/tools/env.sh")"
cd "$root"
exec "$python" -m addon "$@"
