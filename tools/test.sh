#!/usr/bin/env bash
# The test command: sets up .venv if needed, then runs the whole test suite.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
python="$(bash "$root/tools/env.sh")"
cd "$root"
exec "$python" -m pytest -q "$@"
