"""Peak memory of the whole command-line process with the Detail setting Off, Medium and High.

    nice -n 10 .venv/bin/python -m benchmarks.adaptive_memory            # into benchmarks/results/adaptive_memory.md

Each run is a fresh ``python -m addon --scene cornell --patch-size S --detail D --no-preview``
process (memory_cli's: the built-in Cornell box, the estimate, the operator's solve, writing,
saving); its peak resident set is the kernel's for the whole process (``os.wait4``'s
``ru_maxrss``, the child's VmHWM), measured from outside. With Medium and High the run includes
the direct light's refinement and the refining solves (solve_refinement).
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

from benchmarks.memory_cli import MIB, RESULTS, ROOT, _run, _summary_line


def measure(patch_size, detail, error, work):
    blend = work / f"cornell_{detail}.blend"
    log = work / f"{detail}.log"
    args = ["--scene", "cornell", "--patch-size", repr(patch_size), "--error", repr(error), "--detail", detail,
            "-o", str(blend), "-q", "--no-preview"]
    status, peak, seconds = _run([sys.executable, "-m", "addon", *args], log)
    if status:
        raise RuntimeError(f"exit {status}: " + log.read_text()[-3000:])
    return {"detail": detail, "patch_size": patch_size, "error": error, "peak": peak, "seconds": seconds,
            **_summary_line(log)}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--patch-size", type=float, default=0.01)
    ap.add_argument("--error", type=float, default=5.0, help="the error target in %% (default %(default)s)")
    ap.add_argument("--details", nargs="+", default=["OFF", "MEDIUM", "HIGH"])
    ap.add_argument("--out", type=Path, default=RESULTS / "adaptive_memory.md")
    args = ap.parse_args(argv)
    loads = [os.getloadavg()[0]]
    with tempfile.TemporaryDirectory() as tmp:
        runs = [measure(args.patch_size, d, args.error, Path(tmp)) for d in args.details]
    loads.append(os.getloadavg()[0])
    lines = ["# Peak memory with the Detail setting", "",
             f"`python -m benchmarks.adaptive_memory {' '.join(argv if argv is not None else sys.argv[1:])}`; "
             f"machine load {loads[0]:.1f} -> {loads[1]:.1f} (2 cores shared with other jobs). Each row a fresh "
             f"`python -m addon --scene cornell --patch-size {args.patch_size:g} --error {args.error:g} --detail D "
             "--no-preview` process; peak: the kernel's peak resident set of the whole process (ru_maxrss).", "",
             "| detail | patches (final) | paths | solve s | wall s | peak MiB | peak bytes a patch |",
             "|---|---|---|---|---|---|---|"]
    for r in runs:
        lines.append(f"| {r['detail'].lower()} | {r['patches']:,} | {r['paths']:,} | {r['solve_seconds']:.1f} | "
                     f"{r['seconds']:.1f} | {r['peak'] / MIB:,.0f} | {r['peak'] / r['patches']:,.0f} |")
    args.out.write_text("\n".join(lines) + "\n")
    print(args.out.read_text())


if __name__ == "__main__":
    os.chdir(ROOT)
    main()
