#!/usr/bin/env bash
# The test command: sets up .venv if needed, then runs the whole test suite.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
python="$(bash "$root/tools/env.sh")"
cd "$root"
# Two workers, one per core; tests are independent (own temporary folders, free ports).
exec "$python" -m pytest -q -n 2 --durations=15 "$@"
