"""List the sample scenes, or build them as .blend files through the extension.

    .venv/bin/python -m sample_scenes                 # one line per scene: patches, A_T, R_ave, Phi_T
    .venv/bin/python -m sample_scenes --parts NAME    # patches, area and materials of each part
    .venv/bin/python -m sample_scenes --blend out/    # every scene -> out/NAME.blend, solved and baked
                                                      # by the extension (python -m addon --scene NAME)
"""
from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

from . import SCENES, build


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m sample_scenes", description=__doc__.split("\n")[0])
    ap.add_argument("--parts", metavar="NAME", help="print the parts of one scene")
    ap.add_argument("--blend", metavar="DIR", type=Path, help="write DIR/NAME.blend for every scene via the extension")
    ap.add_argument("--scenes", default=",".join(SCENES), help="comma-separated subset (default: all)")
    ap.add_argument("--preview", action="store_true", help="also render a Cycles preview PNG next to each .blend")
    args = ap.parse_args(argv)
    names = [n for n in args.scenes.split(",") if n]
    if args.parts:
        s = build(args.parts)
        print(s.summary())
        for name, n, area, refl, emis in s.part_summary():
            print(f"  {name:18s} {n:7,d} patches  {area:9.4g} m^2  reflectivity {refl}  emittance {emis}")
        return 0
    if args.blend:
        args.blend.mkdir(parents=True, exist_ok=True)
        root = Path(__file__).resolve().parent.parent
        for name in names:
            cmd = [sys.executable, "-m", "addon", "--scene", name, "-o", str(args.blend.resolve() / f"{name}.blend")]
            if not args.preview:
                cmd.append("--no-preview")
            print("$", " ".join(cmd), flush=True)
            subprocess.run(cmd, cwd=root, check=True)
        return 0
    for name in names:
        print(f"{name:12s} {build(name).summary()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
