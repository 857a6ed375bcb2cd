"""Fingerprints of solves of every method, direct light, exit point and stop rule, to show that a
change to how methods are organised leaves their results bit for bit alone.

    python -m benchmarks.hash_solves --write tests/core/pinned_methods.json   # record (on a base commit)
    python -m benchmarks.hash_solves                                            # compare with the record

The cases are ``tests/core/pinned_cases.METHOD_CASES`` (the walk's shot cases are
``CASES``, pinned in ``pinned_results.json``); ``tests/core/test_pinned.py`` checks both.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "core"))

from pinned_cases import METHOD_CASES, SCENES, method_fingerprint, solve_arguments  # noqa: E402

from addon.core import solve  # noqa: E402

PINS = ROOT / "tests" / "core" / "pinned_methods.json"


def fingerprints(cases=METHOD_CASES):
    scenes, out = {}, {}
    for case in cases:
        if case["scene"] not in scenes:
            scenes[case["scene"]] = SCENES[case["scene"]]()
        scene = scenes[case["scene"]]
        out[case["id"]] = method_fingerprint(solve(scene, **solve_arguments(scene, case)))
        print(case["id"], out[case["id"]]["radiosity"], out[case["id"]]["method"], flush=True)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--write", help="record the fingerprints in this file instead of comparing")
    args = ap.parse_args(argv)
    found = fingerprints()
    if args.write:
        Path(args.write).write_text(json.dumps(found, indent=1, sort_keys=True) + "\n")
        print(f"wrote {len(found)} fingerprints to {args.write}")
        return
    pins = json.loads(PINS.read_text())
    differ = [k for k in found if found[k] != pins.get(k)]
    print(f"{len(found) - len(differ)} of {len(found)} the same" + (f"; differ: {differ}" if differ else ""))
    raise SystemExit(1 if differ else 0)


if __name__ == "__main__":
    main()
