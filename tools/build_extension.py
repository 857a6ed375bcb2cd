#!/usr/bin/env python3
"""Build the Blender extension zip of Random Walk Radiosity.

    .venv/bin/python tools/build_extension.py       # download wheels, write the manifest, one zip per platform in dist/
    python tools/build_extension.py --offline       # use the wheels already in build/wheels
    python tools/build_extension.py --platform linux-x64 --python 3.11   # a smaller zip for one platform

Steps:
1. ``pip download --no-deps --only-binary=:all:`` the embreex wheels for each
   Python (cp311: Blender 4.2-4.5, cp313: Blender 5.x) and platform (linux-x64,
   windows-x64, macos-arm64, macos-x64) into ``build/wheels``.  A platform that
   has no wheel on the package index is reported (with the wheels that do
   exist) and left out of the manifest's ``platforms``.
2. Write the ``wheels`` and ``platforms`` lists into ``blender_manifest.toml``
   (the repository's top-level one, unless ``--no-write-manifest``).
3. Stage manifest + ``addon/`` (as the package root) + ``wheels/`` in
   ``build/extension`` and build one zip per platform with Blender's own
   extension builder (``blender_ext.py build --split-platforms``, from the bpy
   module or a Blender install), each validated; without the builder the script
   stops and says how to run it (it never writes an unvalidated zip).
"""

from __future__ import annotations

import argparse
import glob
import os
import re
import shutil
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MANIFEST = os.path.join(ROOT, "blender_manifest.toml")
PACKAGE = "embreex"
VERSION = "4.4.0.post1"
PYTHONS = ["3.11", "3.13"]

# Blender platform -> pip --platform tags to try (newest first is not needed:
# pip takes any of them)
PLATFORMS = {
    "linux-x64": ["manylinux_2_28_x86_64", "manylinux_2_27_x86_64", "manylinux_2_17_x86_64",
                  "manylinux2014_x86_64"],
    "windows-x64": ["win_amd64"],
    "macos-arm64": [f"macosx_{v}_0_arm64" for v in (11, 12, 13, 14, 15)],
    "macos-x64": ["macosx_10_9_x86_64", "macosx_10_13_x86_64"]
    + [f"macosx_{v}_0_x86_64" for v in (11, 12, 13, 14, 15)],
}


def wheel_platform(filename):
    """Blender platform name of a wheel file, or None."""
    tag = filename[:-4].split("-")[-1]
    if "manylinux" in tag and "x86_64" in tag:
        return "linux-x64"
    if tag == "win_amd64":
        return "windows-x64"
    if tag.startswith("macosx") and tag.endswith("arm64"):
        return "macos-arm64"
    if tag.startswith("macosx") and tag.endswith("x86_64"):
        return "macos-x64"
    return None


def wheel_python(filename):
    m = re.search(r"-cp(\d)(\d+)-", filename)
    return f"{m.group(1)}.{m.group(2)}" if m else None


def download(wheels_dir, platforms, pythons, version):
    """Download the wheels; returns {(platform, python): filename or None}."""
    os.makedirs(wheels_dir, exist_ok=True)
    found = {}
    for python in pythons:
        for platform in platforms:
            existing = _find(wheels_dir, platform, python, version)
            if existing:
                found[(platform, python)] = existing
                continue
            cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:",
                   "--python-version", python, "--implementation", "cp", "-d", wheels_dir, "-q",
                   f"{PACKAGE}=={version}"]
            for tag in PLATFORMS[platform]:
                cmd += ["--platform", tag]
            print(f"downloading {PACKAGE} {version} for {platform} cp{python.replace('.', '')} ...", flush=True)
            proc = subprocess.run(cmd, capture_output=True, text=True)
            if proc.returncode != 0:
                print(f"  no wheel: {proc.stderr.strip().splitlines()[-1] if proc.stderr.strip() else 'pip failed'}")
            found[(platform, python)] = _find(wheels_dir, platform, python, version)
    return found


def _find(wheels_dir, platform, python, version):
    for path in sorted(glob.glob(os.path.join(wheels_dir, f"{PACKAGE}-{version}-*.whl"))):
        name = os.path.basename(path)
        if wheel_platform(name) == platform and wheel_python(name) == python:
            return name
    return None


def write_manifest_lists(manifest_text, wheels, platforms):
    """The manifest text with its ``wheels`` and ``platforms`` lists replaced."""
    wheel_block = "wheels = [\n" + "".join(f'  "./wheels/{w}",\n' for w in wheels) + "]"
    text, n = re.subn(r"(?ms)^wheels = \[.*?^\]", wheel_block, manifest_text)
    if n != 1:
        raise SystemExit("blender_manifest.toml: could not find the 'wheels = [...]' list")
    platform_line = "platforms = [" + ", ".join(f'"{p}"' for p in platforms) + "]"
    text, n = re.subn(r"(?m)^platforms = \[.*\]$", platform_line, text)
    if n != 1:
        raise SystemExit("blender_manifest.toml: could not find the 'platforms = [...]' line")
    return text


def blender_ext_script():
    """Blender's extension command-line tool (blender_ext.py), if available.

    Looked up in the bpy module (without importing it) or next to a Blender
    binary given in $BLENDER.
    """
    import importlib.util

    roots = []
    spec = importlib.util.find_spec("bpy")
    if spec is not None and spec.origin:
        roots.append(os.path.dirname(spec.origin))
    if os.environ.get("BLENDER"):
        roots.append(os.path.dirname(os.path.realpath(os.environ["BLENDER"])))
    for base in roots:
        hits = glob.glob(os.path.join(base, "*", "scripts", "addons_core", "bl_pkg", "cli", "blender_ext.py"))
        if hits:
            return hits[0]
    return None


def stage(staging, manifest_text, wheels_dir, wheels):
    if os.path.exists(staging):
        shutil.rmtree(staging)
    shutil.copytree(
        os.path.join(ROOT, "addon"), staging,
        ignore=shutil.ignore_patterns("__pycache__", "*.pyc", ".pytest_cache"),
    )
    with open(os.path.join(staging, "blender_manifest.toml"), "w", encoding="utf-8") as f:
        f.write(manifest_text)
    os.makedirs(os.path.join(staging, "wheels"))
    for w in wheels:
        shutil.copy2(os.path.join(wheels_dir, w), os.path.join(staging, "wheels", w))


def manifest_value(text, key):
    m = re.search(rf'(?m)^{key} = "([^"]+)"', text)
    return m.group(1) if m else None


NO_BUILDER = (
    "Blender's extension builder (blender_ext.py) was not found: it comes with the bpy module or a "
    "Blender install. Run this script with the project's Python (bash tools/env.sh prints it; "
    ".venv/bin/python tools/build_extension.py), or set $BLENDER to a Blender binary")


def build(staging, out_dir, manifest_text):
    """One validated zip per platform (Blender's ``build --split-platforms``), each with only
    its own wheels: their paths, sorted."""
    script = blender_ext_script()
    if not script:
        raise SystemExit(NO_BUILDER)
    os.makedirs(out_dir, exist_ok=True)
    stem = f"{manifest_value(manifest_text, 'id')}-{manifest_value(manifest_text, 'version')}"
    for old in glob.glob(os.path.join(out_dir, f"{stem}*.zip")):
        os.remove(old)
    cmd = [sys.executable, script, "build", "--source-dir", staging, "--output-dir", out_dir, "--split-platforms"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    sys.stdout.write(proc.stdout)
    if proc.returncode != 0:
        sys.stderr.write(proc.stderr)
        raise SystemExit(f"Blender's extension build failed ({script})")
    outputs = sorted(glob.glob(os.path.join(out_dir, f"{stem}*.zip")))
    if not outputs:
        raise SystemExit(f"Blender's extension build wrote no zip into {out_dir}")
    for output in outputs:
        proc = subprocess.run([sys.executable, script, "validate", output], capture_output=True, text=True)
        sys.stdout.write(proc.stdout)
        if proc.returncode != 0:
            sys.stderr.write(proc.stderr)
            raise SystemExit(f"Blender's extension validate failed for {output}")
    return outputs


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--platform", action="append", choices=sorted(PLATFORMS),
                   help="only this platform (repeatable; default: all four)")
    p.add_argument("--python", action="append", choices=PYTHONS, help="only this Python (repeatable)")
    p.add_argument("--version", default=VERSION, help=f"{PACKAGE} version (default {VERSION})")
    p.add_argument("--wheels-dir", default=os.path.join(ROOT, "build", "wheels"))
    p.add_argument("--staging-dir", default=os.path.join(ROOT, "build", "extension"))
    p.add_argument("--out-dir", default=os.path.join(ROOT, "dist"))
    p.add_argument("--offline", action="store_true", help="do not download; use the wheels already there")
    p.add_argument("--no-write-manifest", action="store_true",
                   help="leave the repository's blender_manifest.toml as it is (the zip still gets the lists)")
    args = p.parse_args(argv)
    platforms = args.platform or list(PLATFORMS)
    pythons = args.python or PYTHONS

    if args.offline:
        found = {(pl, py): _find(args.wheels_dir, pl, py, args.version) for pl in platforms for py in pythons}
    else:
        found = download(args.wheels_dir, platforms, pythons, args.version)

    print(f"\n{PACKAGE} {args.version} wheels:")
    complete = []
    for pl in platforms:
        row = [found.get((pl, py)) for py in pythons]
        for py, w in zip(pythons, row):
            print(f"  {pl:12s} cp{py.replace('.', ''):4s} {w or 'MISSING: no wheel on the package index'}")
        if all(row):
            complete.append(pl)
    missing = [pl for pl in platforms if pl not in complete]
    if missing:
        print(f"\nWARNING: no complete set of wheels for {', '.join(missing)}; "
              f"these platforms are left out of the manifest.")
        present = sorted(os.path.basename(w) for w in glob.glob(os.path.join(args.wheels_dir, f"{PACKAGE}-*.whl")))
        print("Wheels present:\n  " + "\n  ".join(present or ["(none)"]))
    if not complete:
        raise SystemExit("no platform has its wheels: nothing to build")
    wheels = sorted(w for (pl, py), w in found.items() if w and pl in complete)

    with open(MANIFEST, encoding="utf-8") as f:
        text = write_manifest_lists(f.read(), wheels, complete)
    full_build = set(platforms) == set(PLATFORMS) and set(pythons) == set(PYTHONS)
    if not args.no_write_manifest and full_build:
        with open(MANIFEST, "w", encoding="utf-8") as f:
            f.write(text)
        print(f"\nwrote wheels and platforms into {os.path.relpath(MANIFEST, ROOT)}")
    stage(args.staging_dir, text, args.wheels_dir, wheels)
    outputs = build(args.staging_dir, args.out_dir, text)
    for output in outputs:
        print(f"built {output} ({os.path.getsize(output) / 1e6:.1f} MB)")
    return outputs


if __name__ == "__main__":
    main()
