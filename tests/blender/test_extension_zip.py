"""The extension zip: built by tools/build_extension.py, installed with
``bpy.ops.extensions.package_install_files`` into a temporary user extension
repository of the bpy module, enabled, used, disabled."""

import json
import os
import re
import subprocess
import sys
import textwrap
import zipfile

import pytest


ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.join(ROOT, "tools"))

import build_extension  # noqa: E402

PY = f"{sys.version_info.major}.{sys.version_info.minor}"


def test_repository_manifest_lists_all_wheels():
    with open(build_extension.MANIFEST, encoding="utf-8") as f:
        text = f.read()
    wheels = re.findall(r'"\./wheels/([^"]+\.whl)"', text)
    seen = {(build_extension.wheel_platform(w), build_extension.wheel_python(w)) for w in wheels}
    expected = {(p, py) for p in build_extension.PLATFORMS for py in build_extension.PYTHONS}
    assert seen == expected
    assert all(w.startswith(f"embreex-{build_extension.VERSION}-") for w in wheels)
    assert re.search(r'(?m)^blender_version_min = "4\.2\.0"$', text)
    assert re.search(r'(?m)^type = "add-on"$', text)


def test_manifest_lists_are_rewritten():
    text = 'platforms = ["a"]\nwheels = [\n  "./wheels/old.whl",\n]\n'
    out = build_extension.write_manifest_lists(text, ["x-1-cp311-cp311-win_amd64.whl"], ["windows-x64"])
    assert out == 'platforms = ["windows-x64"]\nwheels = [\n  "./wheels/x-1-cp311-cp311-win_amd64.whl",\n]\n'


INSTALL_SCRIPT = textwrap.dedent(
    """
    import json, os, sys
    import bpy
    zip_path = sys.argv[-1]
    module = "bl_ext.user_default.random_walk_radiosity"
    out = {}
    out["before"] = hasattr(bpy.types.Scene, "radiosity")
    out["install"] = sorted(bpy.ops.extensions.package_install_files(
        filepath=zip_path, repo="user_default", enable_on_install=True))
    out["enabled"] = module in bpy.context.preferences.addons.keys()
    mod = sys.modules.get(module)
    out["module_file"] = getattr(mod, "__file__", None)
    site = os.path.join(bpy.utils.user_resource("EXTENSIONS"), ".local", "lib",
                        "python%d.%d" % sys.version_info[:2], "site-packages")
    out["wheel_installed"] = os.path.isdir(os.path.join(site, "embreex"))
    out["registered"] = hasattr(bpy.types.Scene, "radiosity")
    # use it: a closed emitting box
    bpy.ops.wm.read_homefile(use_empty=True)
    import bmesh
    me = bpy.data.meshes.new("Box")
    bm = bmesh.new(); bmesh.ops.create_cube(bm, size=1.0); bmesh.ops.reverse_faces(bm, faces=bm.faces[:])
    bm.to_mesh(me); bm.free()
    mat = bpy.data.materials.new("Glow")
    node = mat.node_tree.nodes["Principled BSDF"]
    node.inputs["Base Color"].default_value = (0.5, 0.5, 0.5, 1)
    node.inputs["Emission Color"].default_value = (1, 1, 1, 1)
    node.inputs["Emission Strength"].default_value = 1.0
    me.materials.append(mat)
    ob = bpy.data.objects.new("Box", me); bpy.context.scene.collection.objects.link(ob); ob.select_set(True)
    bpy.context.scene.radiosity.patch_size = 0.5
    bpy.context.scene.radiosity.target_error = 10
    out["solve"] = sorted(bpy.ops.radiosity.solve())
    res = bpy.data.objects.get("Box Radiosity")
    out["attribute"] = res is not None and "Radiosity" in res.data.color_attributes
    bpy.ops.preferences.addon_disable(module=module)
    out["after_disable"] = hasattr(bpy.types.Scene, "radiosity")
    print("RESULT " + json.dumps(out))
    """
)


def test_zip_installs_and_enables_in_the_bpy_module(tmp_path):
    platform = {"linux": "linux-x64", "win32": "windows-x64"}.get(sys.platform)
    if platform is None:
        import platform as _p

        platform = "macos-arm64" if _p.machine() == "arm64" else "macos-x64"
    # a one-platform zip keeps the test small; the wheel cache is reused
    zips = build_extension.main([
        "--platform", platform, "--python", PY, "--no-write-manifest",
        "--staging-dir", str(tmp_path / "staging"), "--out-dir", str(tmp_path / "dist"),
    ])
    # one zip per platform, named after it (Blender's --split-platforms)
    assert len(zips) == 1 and zips[0].endswith(f"-{platform.replace('-', '_')}.zip"), zips
    zip_path = zips[0]
    with zipfile.ZipFile(zip_path) as z:
        names = z.namelist()
    assert "blender_manifest.toml" in names and "__init__.py" in names
    assert "core/__init__.py" in names and "core/mesh/meshing.py" in names
    assert any(n.startswith("wheels/embreex-") for n in names)
    assert not any("__pycache__" in n for n in names)

    env = dict(os.environ)
    env["BLENDER_USER_EXTENSIONS"] = str(tmp_path / "extensions")
    env["BLENDER_USER_CONFIG"] = str(tmp_path / "config")
    env["BLENDER_USER_SCRIPTS"] = str(tmp_path / "scripts")
    env.pop("PYTHONPATH", None)
    script = tmp_path / "install.py"
    script.write_text(INSTALL_SCRIPT)
    proc = subprocess.run(
        [sys.executable, str(script), zip_path], capture_output=True, text=True, env=env,
        cwd=str(tmp_path), timeout=300,
    )
    line = next((l for l in proc.stdout.splitlines() if l.startswith("RESULT ")), None)
    assert line is not None, proc.stdout[-3000:] + proc.stderr[-3000:]
    out = json.loads(line[len("RESULT "):])
    assert out["before"] is False
    assert out["install"] == ["FINISHED"]
    assert out["enabled"] and out["registered"]
    assert out["module_file"].startswith(str(tmp_path / "extensions"))
    assert out["wheel_installed"]
    assert out["solve"] == ["FINISHED"] and out["attribute"]
    assert out["after_disable"] is False


def test_without_blenders_builder_no_unvalidated_zip_is_written(tmp_path, monkeypatch, capsys):
    """A Python without the bpy module (and no $BLENDER) stops with a message saying how to
    build, instead of writing a zip nobody validated."""
    monkeypatch.setattr(build_extension, "blender_ext_script", lambda: None)
    staging = tmp_path / "staging"
    staging.mkdir()
    with pytest.raises(SystemExit) as stop:
        build_extension.build(str(staging), str(tmp_path / "dist"), 'id = "x"\nversion = "1"\n')
    assert "tools/env.sh" in str(stop.value) and not list((tmp_path / "dist").glob("*.zip"))
