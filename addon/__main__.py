"""Command line: build or open a scene, solve, save the .blend, render a preview.

    python -m addon                          # built-in Cornell box -> out/cornell.blend, out/cornell.png
    python -m addon --scene fig1_r0.5        # a scene of sample_scenes/ (see --list)
    python -m addon --open room.blend --select-all --error 3
    blender --background room.blend --python-expr \\
        "import sys; sys.path.insert(0, '/path/to/repo'); from addon.__main__ import main; main(['--current'])"

Runs with the ``bpy`` module (pip package) or inside Blender.  The solve runs
synchronously through the same operator the panel uses (``radiosity.solve``).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import math
import os
import shutil
import signal
import sys
import threading
import time

from . import options  # (numpy and bpy are imported where used: Ctrl-C is handled from the start)


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        """One line, not the whole usage: ``--help`` has the rest."""
        self.exit(2, f"error: {message} (see --help)\n")


def _parser():
    p = _Parser(prog="python -m addon", description=__doc__.split("\n")[0])
    src = p.add_mutually_exclusive_group()
    src.add_argument("--scene", default=None,
                     help="built-in 'cornell' (default) or a sample_scenes name, e.g. fig1_r0.5, cornell_box")
    src.add_argument("--open", metavar="FILE.blend", help="open this .blend and solve its selected meshes")
    src.add_argument("--current", action="store_true", help="use the scene already loaded (inside Blender)")
    p.add_argument("--list", action="store_true", help="list the scene names and exit")
    p.add_argument("--select-all", action="store_true", help="solve all mesh objects, not just the selection")
    p.add_argument("--output", "-o", dest="blend_path", metavar="FILE.blend", help="where to save (default out/<scene>.blend)")
    p.add_argument("--preview", metavar="FILE.png", help="preview image (default: next to the .blend)")
    p.add_argument("--no-preview", action="store_true", help="skip the preview render")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress line")
    for option in options.SETTINGS:  # the panel's settings: same names, defaults and ranges
        if isinstance(option, options.Text):
            p.add_argument(option.flag, dest=option.name, default=option.default, metavar="ADDRESS",
                           help=_literal(option.description))
        elif isinstance(option, options.Flag):
            p.add_argument(option.flag, dest=option.name, default=option.default, action=argparse.BooleanOptionalAction,
                           help=_literal(option.description))
        elif isinstance(option, options.Choice):
            ids = [i for i, _, _ in option.items]
            p.add_argument(option.flag, dest=option.name, default=option.default, metavar="|".join(ids),
                           help=_literal(f"{option.description} (default {option.default}; any case)"))
        else:
            kind = int if option.integer else float
            p.add_argument(option.flag, dest=option.name, type=kind, default=option.default,
                           help=_literal(f"{option.description} ({option.range_text()}; default {option.default:g})"))
    p.add_argument("--resolution", type=int, default=RESOLUTION.default, help=_literal("preview width in pixels "
                   f"({RESOLUTION.range_text()})"))
    p.add_argument("--samples", type=int, default=SAMPLES.default, help=_literal(f"Cycles samples for the preview ({SAMPLES.range_text()})"))
    return p


def _literal(text):
    """A help text as argparse prints it: its own % signs doubled (argparse %-formats help)."""
    return text.replace("%", "%%")


# The preview's own options (not settings of the solve).
RESOLUTION = options.Number("resolution", "--resolution", 480, 16, 16384, "Resolution", "", unit="pixels", integer=True)
SAMPLES = options.Number("samples", "--samples", 16, 1, 65536, "Samples", "", integer=True)


def _checked(args):
    """The arguments with every setting checked against its range (ValueError naming it)."""
    for option in (*options.SETTINGS, RESOLUTION, SAMPLES):
        setattr(args, option.name, option.check(getattr(args, option.name)))
    return args


def _sample_scene_names():
    try:
        import sample_scenes

        return sorted(sample_scenes.SCENES)
    except ImportError:
        return []


def _repo_root():
    return os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _ensure_registered():
    import bpy

    if not hasattr(bpy.types.Scene, "radiosity") or not hasattr(bpy.ops.radiosity, "solve"):
        import addon

        addon.register()


def build_sample_scene(name):
    """Objects for a sample_scenes scene (one object per part, one quad per patch), selected."""
    import bpy
    import sample_scenes
    from sample_scenes.blender import to_blender

    objects = to_blender(sample_scenes.build(name))
    for obj in bpy.context.view_layer.objects:
        obj.select_set(False)
    for obj in objects:
        obj.select_set(True)
    bpy.context.view_layer.objects.active = objects[0]
    return objects


def world_bounds(objects):
    """(lo, hi) corners of the objects' world-space bounding box as Blender evaluates them:
    modifiers applied, and curves, text, surfaces and metaballs as tessellated -- the evaluated
    geometry's vertices (``to_mesh``, read with foreach_get; an evaluated curve's bound box
    holds its control points, not its bevel or extrusion). (0, 0) when there is no geometry."""
    import bpy
    import numpy as np

    depsgraph = bpy.context.evaluated_depsgraph_get()
    lows, highs = [], []
    for o in objects:
        evaluated = o.evaluated_get(depsgraph)
        mesh = evaluated.to_mesh()
        try:
            co = np.empty(3 * len(mesh.vertices), dtype=np.float32)
            mesh.vertices.foreach_get("co", co)
        finally:
            evaluated.to_mesh_clear()
        if not len(co):
            continue
        m = np.array(evaluated.matrix_world, dtype=np.float64)
        points = co.reshape(-1, 3).astype(np.float64) @ m[:3, :3].T + m[:3, 3]
        lows.append(points.min(axis=0))
        highs.append(points.max(axis=0))
    if not lows:
        return np.zeros(3), np.zeros(3)
    return np.min(lows, axis=0), np.max(highs, axis=0)


def _camera_for(objects):
    """A camera inside the bounding box's front, looking in (+y)."""
    import bpy

    lo, hi = world_bounds(objects)
    c = (lo + hi) / 2
    size = hi - lo
    data = bpy.data.cameras.new("Preview Camera")
    data.lens = 18
    cam = bpy.data.objects.new("Preview Camera", data)
    bpy.context.scene.collection.objects.link(cam)
    cam.location = (c[0], lo[1] + 0.02 * size[1], c[2])
    cam.rotation_euler = (math.pi / 2, 0.0, 0.0)
    bpy.context.scene.camera = cam
    return cam


class SceneChanges:
    """Settings changed for the preview, and how to undo them: ``restore()`` sets every value
    back (in the order recorded: a view transform before its look) and then removes what was
    made for the preview (a camera, a world). Restoring never raises."""

    def __init__(self):
        self._values = []  # (owner, name, original value), each setting once
        self._seen = set()
        self._made = []  # callables removing what was created

    def keep(self, *names, owner):
        """Remember the original values of settings that setting others may change (a view
        transform's look, a file format's colour depth), before changing anything."""
        for name in names:
            key = (owner.as_pointer(), name)
            if hasattr(owner, name) and key not in self._seen:
                self._seen.add(key)
                self._values.append((owner, name, getattr(owner, name)))

    def set(self, owner, name, value):
        if hasattr(owner, name):
            self.keep(name, owner=owner)
            setattr(owner, name, value)

    def made(self, remove):
        self._made.append(remove)

    def restore(self):
        failed = []
        for owner, name, value in self._values:
            try:
                if getattr(owner, name) != value:
                    setattr(owner, name, value)
            except Exception:  # noqa: BLE001 - the rest is still restored
                failed.append(name)
        for remove in reversed(self._made):
            try:
                remove()
            except Exception:  # noqa: BLE001
                failed.append(getattr(remove, "__name__", "cleanup"))
        self._values, self._made = [], []
        if failed:
            print(f"warning: could not restore {', '.join(failed)} after the preview", file=sys.stderr)


def preview_settings(scene, sources, width=480, samples=16, exposure=0.0) -> SceneChanges:
    """Set the scene up to render the result objects' baked colours: Cycles without bounces
    (the light transport is in the colours), no denoising, Standard view, the given exposure,
    a black world of its own, PNG output, and a camera if the scene has none. Returns the
    changes, for ``restore()``."""
    import bpy

    changes = SceneChanges()
    render = scene.render
    if scene.camera is None:
        changes.set(scene, "camera", None)
        camera = _camera_for(sources)

        def remove_camera(camera=camera):
            data = camera.data
            bpy.data.objects.remove(camera, do_unlink=True)
            if data is not None and data.users == 0:
                bpy.data.cameras.remove(data)

        changes.made(remove_camera)
        height = int(width * 3 / 4)
    else:  # the scene's own camera and frame shape
        height = max(1, round(width * render.resolution_y / max(render.resolution_x, 1)))
    changes.set(render, "engine", "CYCLES")
    changes.set(scene.cycles, "device", "CPU")
    changes.set(scene.cycles, "samples", samples)
    changes.set(scene.cycles, "max_bounces", 0)  # the light transport is baked in the colours
    changes.set(scene.cycles, "use_denoising", False)
    changes.set(render, "resolution_x", width)
    changes.set(render, "resolution_y", height)
    changes.set(render, "resolution_percentage", 100)
    image = render.image_settings
    changes.keep("media_type", "file_format", "color_mode", "color_depth", owner=image)
    changes.set(image, "media_type", "IMAGE")
    changes.set(image, "file_format", "PNG")
    changes.set(image, "color_management", "FOLLOW_SCENE")
    view = scene.view_settings
    changes.keep("view_transform", "look", owner=view)
    changes.set(view, "view_transform", "Standard")
    changes.set(view, "look", "None")
    changes.set(view, "exposure", exposure)
    # The results only need to be seen (no bounces): as lights, Cycles would build a light tree
    # over every emitting triangle, which at a million patches took more memory than the scene.
    for material in _result_materials(scene):
        changes.set(material.cycles, "emission_sampling", "NONE")
    world = bpy.data.worlds.new("Radiosity Preview World")
    world.color = (0.0, 0.0, 0.0)
    if world.node_tree is not None:
        background = world.node_tree.nodes.get("Background")
        if background is not None:
            background.inputs["Color"].default_value = (0, 0, 0, 1)
    changes.set(scene, "world", world)
    changes.made(lambda world=world: bpy.data.worlds.remove(world))
    changes.keep("filepath", owner=render)
    return changes


def _result_materials(scene):
    """The materials of the scene's result objects (ours, and any the user gave them)."""
    from .blender_write.results import previous_results

    materials = {}
    for obj in previous_results(scene):
        for slot in obj.material_slots:
            if slot.material is not None:
                materials[slot.material.name] = slot.material
    return list(materials.values())


def render_preview(path, sources, width=480, samples=16, exposure=0.0, keep_settings=False, write_to=None):
    """Render the result objects (their baked colours as emission) with Cycles to ``path``
    (the scene's output path), written to ``write_to`` if given (a temporary file).

    The source objects are hidden from the render while it runs; they and the preview's
    settings (``preview_settings``) are restored afterwards unless ``keep_settings`` (a scene
    built here is saved so that F12 renders what the preview shows).
    """
    import bpy

    scene = bpy.context.scene
    changes = preview_settings(scene, sources, width, samples, exposure)
    hidden = [(o, o.hide_render) for o in sources]
    try:
        for o, _ in hidden:
            o.hide_render = True
        scene.render.filepath = os.path.abspath(path)
        bpy.ops.render.render()
        result = next(i for i in bpy.data.images if i.type == "RENDER_RESULT")
        result.save_render(filepath=os.path.abspath(write_to or path), scene=scene)
    finally:
        if not keep_settings:
            for o, h in hidden:
                o.hide_render = h
            changes.restore()


def _one_line(exc) -> str:
    """An error raised through ``bpy.ops`` (RuntimeError 'Error: ...') as one line."""
    lines = [line.strip() for line in str(exc).strip().splitlines() if line.strip()]
    if any(line.startswith("Traceback") or "Python: Traceback" in line for line in lines):
        lines = lines[-1:]  # an exception inside an operator: its last line says what
    text = " ".join(lines)
    for prefix in ("Error:", "Python:"):
        if text.startswith(prefix):
            text = text[len(prefix):].strip()
    return text or type(exc).__name__


def _fail(message, status=1):
    print(f"error: {message}", file=sys.stderr)
    return status


def main(argv=None):
    args = _parser().parse_args(sys.argv[1:] if argv is None else argv)
    try:
        args = _checked(args)
    except ValueError as exc:
        return _fail(str(exc), 2)
    names = ["cornell"] + _sample_scene_names()
    if args.list:
        print("\n".join(names))
        return 0
    with Interrupt() as interrupt:
        try:
            return _run(args, names, interrupt)
        except Interrupted:
            return interrupt.stopped()


def _run(args, names, interrupt):
    root = _repo_root()
    if root not in sys.path:
        sys.path.insert(0, root)
    import bpy

    from .blender_read.objects import source_objects
    from .blender_write.results import is_result_object

    interrupt.check()
    t0 = time.perf_counter()
    scene_name = args.scene or "cornell"
    if args.open:
        path = os.path.abspath(args.open)
        if not os.path.isfile(path):
            return _fail(f"no such file: {path}", 2)
        try:
            bpy.ops.wm.open_mainfile(filepath=path)
        except RuntimeError as exc:
            return _fail(f"cannot open {path}: {_one_line(exc)}", 2)
        scene_name = os.path.splitext(os.path.basename(args.open))[0]
    elif args.current:
        scene_name = os.path.splitext(os.path.basename(bpy.data.filepath))[0] or "scene"
    else:
        bpy.ops.wm.read_factory_settings(use_empty=True)
    _ensure_registered()
    own_scene = not (args.open or args.current)  # built here, not the user's
    if own_scene:
        if scene_name == "cornell":  # the one Cornell box: sample_scenes/cornell_box.py
            build_sample_scene("cornell_box")
        elif scene_name in _sample_scene_names():
            build_sample_scene(scene_name)
        else:
            return _fail(f"unknown scene {scene_name!r}; choose from: {', '.join(names)}", 2)
    out_blend = os.path.abspath(args.blend_path or os.path.join("out", f"{scene_name}.blend"))
    png = None if args.no_preview else os.path.abspath(args.preview or os.path.splitext(out_blend)[0] + ".png")
    for target in (out_blend, png):  # said before the run, not after it
        problem = target and output_problem(target)
        if problem:
            return _fail(problem, 2)
    if args.select_all:
        for o in bpy.context.view_layer.objects:
            o.select_set(o.type == "MESH" and not is_result_object(o))
    sources = source_objects(bpy.context)
    if not sources:
        return _fail("no mesh object selected (use --select-all)", 2)

    settings = bpy.context.scene.radiosity
    if own_scene and scene_name in _sample_scene_names() and not args.patch_size:
        args.patch_size = 1e6  # sample scenes come meshed as in the paper: keep their patches
    for option in options.SETTINGS:
        setattr(settings, option.name, getattr(args, option.name))

    from . import pipeline
    from .blender_read.selection import read_selection
    from .bpy_free import worker
    from .ui import operators

    try:  # a costly setting is said before the run, as the panel says it
        warning = pipeline.estimate(read_selection(bpy.context)[0], settings.solve_settings())["warning"]
    except ValueError:
        warning = None  # bad input: the solve says what is wrong
    interrupt.check()
    if warning:
        print(f"warning: {warning}", file=sys.stderr)
    operators.LAST_ERROR = ""
    progress = ProgressLine(sys.stderr) if (not args.quiet and sys.stderr.isatty()) else None
    interrupt.progress = progress
    worker.PROGRESS_LISTENER = progress
    exposure = []

    def before_writing(output):
        if not args.no_preview:  # from the arrays written: reading Blender's back would copy them
            exposure.append(preview_exposure(output, settings.output))
        release_solve_memory()  # writing the colours needs the patches, not the core's scene

    operators.OUTPUT_LISTENER = before_writing
    reports = io.StringIO()  # the operator's reports, after the progress line, on lines of their own
    try:
        with contextlib.redirect_stdout(reports):
            result = bpy.ops.radiosity.solve(quiet_errors=True)
    except RuntimeError as exc:  # an error the operator did not keep quiet
        return _fail(_one_line(exc))
    finally:
        worker.PROGRESS_LISTENER = None
        operators.OUTPUT_LISTENER = None
        if progress is not None:
            progress.end()
        interrupt.check()
        sys.stdout.write(reports.getvalue())
    release_solve_memory()
    if "FINISHED" not in result:
        return _fail(operators.LAST_ERROR or "the solve did not finish")
    print(summary(scene_name, settings))
    print(f"sources: {settings.last_sources}")
    outputs = interrupt.outputs = Outputs()
    try:
        for target in (out_blend, png):
            if target:
                os.makedirs(os.path.dirname(target), exist_ok=True)
        outputs.add(out_blend, check_blend)
        if png:
            outputs.add(png, check_png)
        if png and own_scene:
            # a scene built here: saved with the preview's settings, so F12 renders the same
            render_preview(png, sources, args.resolution, args.samples, exposure[-1] if exposure else _auto_exposure(),
                           keep_settings=True, write_to=outputs.writing(png))
            interrupt.check()
        # the user's scene is saved as it is, plus the results (a copy: the open file stays the same)
        save_blend(outputs.writing(out_blend))
        interrupt.check()
        if png and not own_scene:
            # then the preview, with temporary settings undone afterwards
            render_preview(png, sources, args.resolution, args.samples,
                           exposure[-1] if exposure else _auto_exposure(), write_to=outputs.writing(png))
        outputs.check()
        with interrupt.lock:  # all files in place, or none
            interrupt.check()
            outputs.commit()
            interrupt.committed = True
    except (RuntimeError, OSError) as exc:
        outputs.discard()
        return _fail(outputs.failure(exc))
    if png:
        print(f"preview: {png}")
    print(f"saved: {out_blend}  ({time.perf_counter() - t0:.1f} s in all)")
    return 0


def output_problem(path):
    """Why ``path`` cannot be written (a folder on the way is a file, or not writable), or None."""
    if os.path.isdir(path):
        return f"cannot write {path}: it is a folder"
    folder = os.path.dirname(path)
    existing = folder
    while not os.path.exists(existing):
        existing = os.path.dirname(existing)
    if not os.path.isdir(existing):
        return f"cannot create the folder {folder}: {existing} is a file"
    if not os.access(existing, os.W_OK | os.X_OK):
        return f"cannot write in {existing}: permission denied"
    return None


def save_blend(path):
    """Save the open file's data to ``path`` as a copy (the open file keeps its name), without
    Blender's report naming ``path`` (a temporary name)."""
    import bpy

    with contextlib.redirect_stdout(io.StringIO()):
        bpy.ops.wm.save_as_mainfile(filepath=path, copy=True)


def check_blend(path):
    """Raise OSError unless Blender reads ``path`` back as a .blend file (a truncated one, e.g. on
    a full disk, lacks its DNA block)."""
    import bpy

    if os.path.getsize(path) == 0:
        raise OSError("the file written is empty")
    try:
        with bpy.data.libraries.load(path) as (_data_from, _data_to):
            pass
    except OSError as exc:
        reason = _one_line(exc).rsplit(": ", 1)[-1]
        raise OSError(f"the file written does not read back ({reason})") from None


PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
PNG_END = b"\x00\x00\x00\x00IEND\xaeB`\x82"  # the empty IEND chunk that ends every PNG


def check_png(path):
    """Raise OSError unless ``path`` is a whole PNG file (its signature, and its IEND chunk last)."""
    with open(path, "rb") as f:
        head = f.read(len(PNG_SIGNATURE))
        f.seek(0, os.SEEK_END)
        f.seek(max(f.tell() - len(PNG_END), 0))
        tail = f.read()
    if head != PNG_SIGNATURE or tail != PNG_END:
        raise OSError("the image written is incomplete")


class Outputs:
    """The run's files, each written beside its target under a temporary name (the same folder:
    relative paths in a .blend stay right, and the rename is atomic), checked, then put in place
    together: until then an earlier file of the same name stays as it was."""

    def __init__(self):
        self.files = []  # (temporary path, target, check: raises OSError unless the file is whole)
        self.existed = set()
        self.stage = None  # the target being written

    def add(self, target, check):
        folder, name = os.path.split(target)
        stem, ext = os.path.splitext(name)
        self.files.append((os.path.join(folder, f".{stem}.{os.getpid()}.partial{ext}"), target, check))
        if os.path.exists(target):
            self.existed.add(target)

    def writing(self, target):
        """The temporary path to write ``target``'s content to."""
        self.stage = target
        return next(path for path, t, _ in self.files if t == target)

    def check(self):
        for path, target, check in self.files:
            self.stage = target
            check(path)
        self.stage = None

    def commit(self):
        for path, target, _ in self.files:
            self.stage = target
            os.replace(path, target)
        self.files, self.stage = [], None

    def discard(self):
        """Remove the temporary files (and Blender's own temporary, "<path>@"); never raises."""
        for path, _, _ in self.files:
            for name in (path, path + "@"):
                with contextlib.suppress(OSError):
                    os.remove(name)

    def failure(self, exc):
        """The one line saying what failed, and that the earlier files are kept."""
        reason = _one_line(exc) if isinstance(exc, RuntimeError) else (exc.strerror or str(exc))
        where = f" {self.stage}" if self.stage else ""
        kept = "; the earlier file is kept" if self.existed else "; nothing was saved"
        if isinstance(exc, OSError) and exc.filename and not self.stage:
            where = f" {exc.filename}"
        return f"cannot save{where}: {reason}{kept}"


class Interrupted(Exception):
    """Ctrl-C was pressed: the run stops at the next point that can stop."""


class Interrupt:
    """Ctrl-C on the command line: the running solve is cancelled, nothing is saved (the files
    are put in place only at the end, ``Outputs``), one line is printed and the status is 130.

    The main thread stops at its next ``check()``; when it cannot (held in Blender's C code, a
    render or a save), a watchdog thread woken by the signal (``signal.set_wakeup_fd``) ends the
    process GRACE seconds later, with the same line and status, after removing the temporary
    files. Installed only over Python's own SIGINT handler, on the main thread."""

    GRACE = 0.5
    STATUS = 130
    MESSAGE = "interrupted: stopped by Ctrl-C; nothing was saved"

    def __init__(self):
        self.requested = threading.Event()
        self.finished = threading.Event()
        self.lock = threading.Lock()  # held while the files are put in place
        self.committed = False
        self.progress = None  # the ProgressLine to end
        self.outputs = None  # the Outputs to discard
        self._pipe = None

    def __enter__(self):
        if (threading.current_thread() is not threading.main_thread()
                or signal.getsignal(signal.SIGINT) is not signal.default_int_handler):
            return self  # someone else's handler (Blender's, a host's): left alone
        read, write = os.pipe()
        os.set_blocking(write, False)
        self._wakeup = signal.set_wakeup_fd(write, warn_on_full_buffer=False)
        self._previous = signal.signal(signal.SIGINT, self._on_signal)
        self._pipe = (read, write)
        self._watchdog = threading.Thread(target=self._watch, name="radiosity-interrupt", daemon=True)
        self._watchdog.start()
        return self

    def __exit__(self, *exc_info):
        self.finished.set()
        if self._pipe is not None:
            signal.signal(signal.SIGINT, self._previous)
            signal.set_wakeup_fd(self._wakeup)
            os.close(self._pipe[1])  # the watchdog reads the end of the pipe and ends
            self._watchdog.join(timeout=1)
            os.close(self._pipe[0])
            self._pipe = None
        return False

    def _on_signal(self, signum, frame):  # (main thread, between two Python steps: never raises)
        self._request()

    def _request(self):
        self.requested.set()
        worker = sys.modules.get(f"{__package__}.bpy_free.worker")  # (no import here: it could wait on the main thread's)
        job = worker.running_job() if worker is not None else None
        if job is not None:
            job.cancel()

    def check(self):
        if self.requested.is_set():
            raise Interrupted

    def stopped(self):
        """The main thread's way out after Ctrl-C: discard, one line, the status."""
        with self.lock:
            self._leave()
        return self.STATUS

    def _leave(self):
        self.finished.set()
        if self.progress is not None:
            self.progress.end()
        if self.outputs is not None:
            self.outputs.discard()
        at_start = "\r" if _isatty(sys.stderr) else ""  # (over the "^C" the terminal echoed)
        print(at_start + self.MESSAGE, file=sys.stderr, flush=True)

    def _watch(self):
        read = self._pipe[0]
        while True:
            try:
                data = os.read(read, 64)
            except OSError:
                return
            if not data or self.finished.is_set():
                return
            if signal.SIGINT not in data:
                continue
            self._request()
            if self.finished.wait(self.GRACE):
                return
            with self.lock:  # (a commit under way ends first: its files are whole)
                if self.finished.is_set() or self.committed:
                    return
                self._leave()
                exit_now(self.STATUS)


def _isatty(stream):
    try:
        return stream.isatty()
    except (AttributeError, ValueError):
        return False


def exit_now(status):
    """End the process at once (Blender's own exit takes half a second): streams flushed and
    Blender's session folder removed, as its exit would."""
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    blender_tempdir = None
    with contextlib.suppress(Exception):  # (bpy may still be importing: its folder exists already)
        blender_tempdir = sys.modules["bpy"].app.tempdir
    if blender_tempdir and os.path.basename(os.path.normpath(blender_tempdir)).startswith("blender_"):
        shutil.rmtree(blender_tempdir, ignore_errors=True)
    os._exit(status)


def release_solve_memory():
    """Let go of what the solve kept for the panel (the meshed geometry and the core's scene with
    its ray tracer, kept for a re-run) and give it back to the system: the command line saves and
    renders next, and Cycles' copy of the results needs the room."""
    import gc

    from .bpy_free import patches, trim

    patches._GEOMETRY_CACHE.clear()
    gc.collect()
    trim.give_back()


def summary(scene_name, settings) -> str:
    """The run in one line, with the error reached against the target (both relative RMS)."""
    error = settings.last_relative_error
    target = settings.last_target_error
    reached = "error unknown" if error < 0 else f"error {error:.2f}%"
    if target > 0 and error >= 0:
        reached += f" of a {target:g}% target ({error / target * 100:.0f}% of it)"
    return (f"{scene_name}: {settings.last_patches:,} patches, {settings.last_paths:,} paths, "
            f"{settings.last_rays:,} rays, {settings.last_seconds:.2f} s ({settings.last_estimator}), mean path length "
            f"{settings.last_mean_path_length:.2f}, {reached}, stopped by {settings.last_stopped}")


class ProgressLine:
    """One line on a terminal, rewritten after batches (at most every PERIOD seconds): paths
    done of planned, ray rate, the error estimate against the target, and the time left.
    Cut to the terminal's width: a line that wraps cannot be rewritten, each rewrite would
    leave a line behind."""

    PERIOD = 0.25

    def __init__(self, stream):
        self.stream, self.shown, self.width = stream, 0.0, 0
        self._lock = threading.Lock()  # (ended by the interrupt's watchdog too)

    def __call__(self, job):
        now = time.perf_counter()
        if now - self.shown < self.PERIOD:
            return
        self.shown = now
        self.write(progress_text(job))

    def write(self, text):
        with self._lock:
            text = text[:terminal_columns(self.stream) - 1]
            self.stream.write("\r" + text.ljust(self.width))
            self.stream.flush()
            self.width = len(text)

    def end(self):
        """Clear the line (and a "^C" the terminal echoed after it)."""
        with self._lock:
            if self.width:
                blank = min(self.width + 2, terminal_columns(self.stream) - 1)
                self.stream.write("\r" + " " * blank + "\r")
                self.stream.flush()
                self.width = 0


def terminal_columns(stream) -> int:
    """The width of the terminal ``stream`` writes to (80 where it does not say)."""
    try:
        columns = os.get_terminal_size(stream.fileno()).columns
    except (AttributeError, ValueError, OSError, io.UnsupportedOperation):
        columns = 0
    return columns if columns > 1 else 80


def progress_text(job) -> str:
    """The progress line of a running job (worker.SolveJob)."""
    p = job.snapshot()
    fraction, paths, seconds = p.get("fraction", 0.0), p.get("paths", 0), p.get("seconds", 0.0)
    planned = p.get("expected_paths", math.nan)  # where the run is expected to end, from its measured error
    planned = int(planned) if planned == planned and planned is not None else getattr(job.prediction, "paths", None)
    parts = [f"{fraction * 100:5.1f}%", f"{paths:,} of {planned:,} expected paths" if planned else f"{paths:,} paths"]
    if p.get("rays_per_second"):
        parts.append(f"{p['rays_per_second'] / 1e6:.2f} Mray/s")
    error = job.relative_error(p.get("measured_mse"))
    if error is not None:
        target = job.settings.relative_rms
        parts.append(f"error {error * 100:.2f}%" + (f" (target {target * 100:g}%)" if not job.settings.paths else ""))
    left = p.get("seconds_left", math.nan)
    if left == left and left is not None and fraction < 1:  # (NaN until the run has measured its error)
        parts.append(f"{int(left // 60)}:{int(left % 60):02d} left")
    return "  ".join(parts)


def _auto_exposure():
    """Exposure (stops) that maps the median reflected radiosity to 0.35, from the result
    objects' colours as written in Blender (reading them back makes Blender copy them)."""
    import numpy as np

    from .blender_write.results import ATTRIBUTE_NAME, previous_results

    values = []
    for obj in previous_results():
        attr = obj.data.color_attributes.get(ATTRIBUTE_NAME)
        if attr is None:
            continue
        c = np.empty(len(attr.data) * 4, dtype=np.float32)
        attr.data.foreach_get("color", c)
        values.append(c.reshape(-1, 4)[:, :3].mean(axis=1))
    return _exposure_of(values)


def preview_exposure(output, mode) -> float:
    """``_auto_exposure`` of the results a solve's ``output`` (pipeline.SolveOutput) writes in
    colour mode ``mode``, from its arrays: the 'Radiosity' attribute's values (per patch on every
    corner, or per point with VERTEX), as the float32 colours written."""
    import numpy as np

    from .blender_write.results import rgba

    values = []
    for mesh, faces, points in zip(output.patches.meshes, output.face_colours, output.point_colours):
        if faces is None:  # the rest of the scene: no results
            continue
        shown = points if mode == "VERTEX" else faces
        grey = rgba(shown).reshape(-1, 4)[:, :3].mean(axis=1)
        values.append(grey if mode == "VERTEX" else np.repeat(grey, mesh.face_sizes))
    return _exposure_of(values)


def _exposure_of(values):
    """Exposure (stops) that maps the median of the positive values (arrays) to 0.35."""
    import numpy as np

    if not values:
        return 0.0
    v = np.concatenate(values)
    v = v[v > 0]
    if not len(v):
        return 0.0
    median = float(np.median(v))
    return float(np.clip(math.log2(0.35 / median), -10, 10)) if median > 0 else 0.0


if __name__ == "__main__":
    try:
        status = main()
    except KeyboardInterrupt:  # before the run's own handler was in place
        print(Interrupt.MESSAGE, file=sys.stderr)
        status = Interrupt.STATUS
    if status == Interrupt.STATUS:
        exit_now(status)
    sys.exit(status)
