"""The glue's house: each module does one job (short modules, short functions), and its folders
show the layers -- what reads Blender, what writes it, the user interface, the command line, and
the middle that needs no bpy (checked by reading the code with ast, nothing is imported).

The core is held to the same sizes (its modules to about 400 lines: at most 420)."""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

ADDON = Path(__file__).resolve().parents[1] / "addon"
MAX_MODULE_LINES = 400
MAX_CORE_MODULE_LINES = 420  # (about 400: lights of every kind and the grids' tables stay whole)
MAX_FUNCTION_LINES = 60

#: The layers of the glue: folder -> what it holds.
LAYERS = {
    "blender_read": "reads the Blender scene into arrays",
    "blender_write": "writes results into Blender",
    "ui": "the panel, its properties, the operators, the live view",
    "cli": "the command line",
    "bpy_free": "the middle on arrays: patches, the worker thread, memory given back; no bpy",
}
#: Modules that use Blender, whatever they import (they are handed its objects).
BLENDER = {"bpy", "bmesh", "gpu", "gpu_extras", "mathutils", "bl_math"}


def _glue():
    return [p for p in sorted(ADDON.rglob("*.py"))
            if "core" not in p.relative_to(ADDON).parts[:1]]


def _name(path):
    return path.relative_to(ADDON).as_posix()


def _imports(path):
    """(top-level names of absolute imports, targets of relative imports as 'a.b') of a module,
    wherever in it they are (imports inside functions count)."""
    absolute, relative = set(), set()
    package = path.relative_to(ADDON).parent.parts
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            absolute |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0:
            absolute.add(node.module.split(".")[0])
        elif isinstance(node, ast.ImportFrom):
            base = package[: len(package) - (node.level - 1)]
            module = [*base, *(node.module.split(".") if node.module else [])]
            targets = [module] if node.module else [[*module, a.name] for a in node.names]
            relative |= {".".join(t) for t in targets}
    return absolute, relative


def test_the_glue_is_in_folders_by_layer():
    present = {p.name for p in ADDON.iterdir() if p.is_dir() and (p / "__init__.py").exists()}
    assert set(LAYERS) <= present, "layer folders missing"
    for layer in LAYERS:
        assert len(list((ADDON / layer).glob("*.py"))) > 1, f"addon/{layer}/ holds no module"
    loose = {p.name for p in ADDON.glob("*.py")} - {"__init__.py", "__main__.py"}
    assert loose == set(), "glue modules outside the layer folders"


def _core():
    return sorted((ADDON / "core").rglob("*.py"))


@pytest.mark.parametrize("path, most", [(p, MAX_MODULE_LINES) for p in _glue()] + [(p, MAX_CORE_MODULE_LINES) for p in _core()],
                         ids=lambda value: _name(value) if isinstance(value, Path) else str(value))
def test_a_module_is_short_and_so_are_its_functions(path, most):
    """Every glue module at most 400 lines, every core module about that (at most 420), and every
    function of either at most 60."""
    text = path.read_text()
    lines = len(text.splitlines())
    assert lines <= most, f"{_name(path)} has {lines} lines, over {most}"
    long = [f"{node.name} ({node.end_lineno - node.lineno + 1} lines)" for node in ast.walk(ast.parse(text))
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
            and node.end_lineno - node.lineno + 1 > MAX_FUNCTION_LINES]
    assert long == [], f"{_name(path)}: functions over {MAX_FUNCTION_LINES} lines: {long}"


def _modules(layer):
    found = sorted((ADDON / layer).glob("*.py"))
    assert found, f"addon/{layer}/ holds no module"
    return found


def test_the_bpy_free_middle_never_imports_blender_nor_the_layers_that_do():
    for path in _modules("bpy_free"):
        absolute, relative = _imports(path)
        assert absolute & BLENDER == set(), f"{_name(path)} imports Blender's modules"
        above = {t for t in relative if t.split(".")[0] in {"blender_read", "blender_write", "ui", "cli"}}
        assert above == set(), f"{_name(path)} imports a layer that uses Blender"


def test_reading_and_writing_blender_never_import_the_interface():
    for layer in ("blender_read", "blender_write"):
        for path in _modules(layer):
            _, relative = _imports(path)
            assert {t for t in relative if t.split(".")[0] in {"ui", "cli"}} == set(), _name(path)


def test_the_core_never_imports_the_glue():
    for path in sorted((ADDON / "core").rglob("*.py")):
        _, relative = _imports(path)
        outside = {t for t in relative if not t.startswith("core")}
        assert outside == set(), f"{_name(path)} imports the glue"


TESTS = Path(__file__).resolve().parent


def test_the_tests_mirror_the_code():
    """Each folder of tests is named for the part of the code it tests (addon/core, a glue layer,
    the benchmarks), the Blender tests for the glue layer they drive; the solver, the pipeline
    and the reading of the selection each have a test file of their name."""
    code = {"core", "bpy_free", "benchmarks", "blender", "sample_scenes"}
    folders = {p.name for p in TESTS.iterdir() if p.is_dir() and not p.name.startswith((".", "_"))}
    assert folders <= code, folders - code
    blender = {p.name for p in (TESTS / "blender").iterdir() if p.is_dir() and not p.name.startswith("_")}
    assert blender <= set(LAYERS), blender - set(LAYERS)
    for part in ("core", "bpy_free"):
        modules = {p.stem for p in (ADDON / part).rglob("*.py")} | {p.name for p in (ADDON / part).iterdir() if p.is_dir()}
        for test in (TESTS / part).glob("test_*.py"):
            assert test.stem[5:] in modules or test.stem[5:] in CROSS_CUTTING, f"{part}/{test.name} names no module of addon/{part}"
    for named in ("core/test_solver.py", "bpy_free/test_pipeline.py", "blender/blender_read/test_selection.py"):
        assert (TESTS / named).exists(), named


# Tests of the whole solve against references, named for what they check, not for a module.
CROSS_CUTTING = {
    "energy", "error_model", "exact_reference", "furnace", "stress", "two_way_stress", "variance", "pinned",
    "properties", "stratified", "economy", "groups", "memory", "error_promise", "two_sided",
}


# ---------------------------------------------------------------------------------------------
# Arrows one way: the import graph of every module of addon/, and of every folder's rooms
# ---------------------------------------------------------------------------------------------
#: The core's packages, and at most how many modules each holds (about 12).
MAX_CORE_PACKAGES = 10
MAX_PACKAGE_MODULES = 13


def _module_name(path):
    parts = list(path.relative_to(ADDON.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _is_module(dotted):
    base = ADDON.parent / dotted.replace(".", "/")
    return base.with_suffix(".py").exists() or (base / "__init__.py").exists()


def _graph():
    """{module: the modules of addon/ it imports}, imports inside functions included."""
    graph = {}
    for path in sorted(ADDON.rglob("*.py")):
        name = _module_name(path)
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        targets = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                targets |= {a.name for a in node.names if a.name.startswith("addon")}
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                    module = ".".join(base + ([node.module] if node.module else []))
                else:
                    module = node.module
                if not module.startswith("addon"):
                    continue
                named = {f"{module}.{a.name}" for a in node.names if _is_module(f"{module}.{a.name}")}
                targets |= named or {module}
                if named and len(named) < len(node.names):
                    targets.add(module)
        graph[name] = targets - {name}
    return graph


def _circles(graph):
    """The strongly connected sets of more than one node of ``graph`` (Tarjan's)."""
    index, low, stack, on, found, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in graph:
                continue
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            part = set()
            while True:
                w = stack.pop()
                on.discard(w)
                part.add(w)
                if w == v:
                    break
            if len(part) > 1:
                found.append(sorted(part))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def _faces():
    """Package faces: __init__ modules that only hand names on (no function or class)."""
    faces = set()
    for path in ADDON.rglob("__init__.py"):
        tree = ast.parse(path.read_text())
        if not any(isinstance(n, (ast.FunctionDef, ast.ClassDef)) for n in tree.body):
            faces.add(_module_name(path))
    return faces


def test_no_import_circle_anywhere():
    """No module of addon/ reaches itself through imports, an import inside a function included."""
    assert _circles(_graph()) == []


@pytest.mark.parametrize("folder", sorted({p.parent for p in ADDON.rglob("__init__.py")}),
                         ids=lambda p: _name(p) or "addon")
def test_every_folders_rooms_import_one_way(folder):
    """Looked at folder by folder (each subfolder one room, each module of the folder one), the
    arrows between rooms run one way: no circle among a folder's parts either."""
    graph, faces = _graph(), _faces()
    prefix = _module_name(folder / "__init__.py")

    def room(module):
        if not (module + ".").startswith(prefix + ".") or module == prefix:
            return None
        return prefix + "." + module[len(prefix) + 1:].split(".")[0]

    rooms = {}
    for module, targets in graph.items():
        here = room(module)
        if here is None or module in faces:
            continue
        rooms.setdefault(here, set())
        rooms[here] |= {room(t) for t in targets if room(t) not in (None, here) and t not in faces}
    assert _circles(rooms) == []


def test_no_private_name_is_used_across_modules():
    """A module uses another module of addon/ through its public names alone: no ``_name``
    imported from it, and no ``module._name`` read of one imported."""
    found = []
    for path in sorted(ADDON.rglob("*.py")):
        tree = ast.parse(path.read_text())
        modules = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and (node.level or (node.module or "").startswith("addon")):
                for a in node.names:
                    if a.name.startswith("_") and not a.name.startswith("__"):
                        found.append(f"{_name(path)}:{node.lineno} imports {a.name}")
                    modules.add(a.asname or a.name)
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in modules \
                    and node.attr.startswith("_") and not node.attr.startswith("__"):
                found.append(f"{_name(path)}:{node.lineno} reads {node.value.id}.{node.attr}")
    assert found == []


def test_the_core_is_a_few_packages_each_saying_what_it_holds():
    """The core is at most MAX_CORE_PACKAGES packages of at most MAX_PACKAGE_MODULES modules, each
    package's face one docstring saying what it holds; beside them at its top only the public
    face, the names, the settings and the solve's own modules."""
    core = ADDON / "core"
    packages = sorted(p for p in core.iterdir() if (p / "__init__.py").exists())
    assert len(packages) <= MAX_CORE_PACKAGES, [p.name for p in packages]
    for package in packages:
        modules = [p for p in package.glob("*.py") if p.name != "__init__.py"]
        assert len(modules) <= MAX_PACKAGE_MODULES, (package.name, len(modules))
        doc = ast.get_docstring(ast.parse((package / "__init__.py").read_text()))
        assert doc and len(doc.splitlines()[0]) <= 110, package.name  # (its first line says it)
    top = {p.stem for p in core.glob("*.py")}
    assert top == {"__init__", "names", "settings", "solver", "chunks", "forecast"}, top
