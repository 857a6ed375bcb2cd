"""The command line's arguments: the panel's settings (one table, ``options``) as flags with
the same names, defaults and ranges, and the preview's own (resolution, samples)."""

from __future__ import annotations

import argparse

from ..bpy_free import options

DESCRIPTION = "Command line: build or open a scene, solve, save the .blend, render a preview."


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        """One line, not the whole usage: ``--help`` has the rest."""
        self.exit(2, f"error: {message} (see --help)\n")


def parser():
    p = _Parser(prog="python -m addon", description=DESCRIPTION)
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
    p.add_argument("--relight", action="store_true", help="no solve: recombine the opened file's per-light results "
                   "with the strengths and colours given (no ray traced), then save")
    p.add_argument("--strength", action="append", metavar="NAME=VALUE",
                   help="with --relight: a lamp's power, the world's or an emissive material's strength")
    p.add_argument("--colour", action="append", metavar="NAME=R,G,B", help="with --relight: its colour")
    for option in options.SETTINGS:  # the panel's settings: same names, defaults and ranges
        if isinstance(option, options.Text):
            p.add_argument(option.flag, dest=option.name, default=option.default, metavar="ADDRESS",
                           help=_literal(option.description))
        elif isinstance(option, options.Flag):
            p.add_argument(option.flag, dest=option.name, default=option.default, action=argparse.BooleanOptionalAction,
                           help=_literal(option.description))
        elif isinstance(option, options.Choice):
            ids = [i for i, _, _ in option.items]
            labels = "".join(f"{i}: {label}, " for i, label, _ in option.items if label.lower() != i.lower())
            p.add_argument(option.flag, dest=option.name, default=option.default, metavar="|".join(ids),
                           help=_literal(f"{option.description} ({labels}default {option.default}; any case)"))
        else:
            kind = int if option.integer else float
            p.add_argument(option.flag, dest=option.name, type=kind, default=option.default, help=_literal(
                f"{option.description} ({option.range_text()}; default {option.number_text(option.default)})"))
    p.add_argument("--resolution", type=int, default=RESOLUTION.default, help=_literal("preview width in pixels "
                   f"({RESOLUTION.range_text()}; default {RESOLUTION.default})"))
    p.add_argument("--samples", type=int, default=None, help=_literal(
        f"Cycles samples for the preview ({SAMPLES.range_text()}; default {LIVE_SAMPLES} with live lamps on textured "
        f"results, denoised: a Monte Carlo render; {SAMPLES.default} with --no-live-lamps or another output, which "
        "has no noise to average)"))
    return p


def given_options(argv):
    """The names of the settings the command line gives (``--error 2``, ``--error=2``, ``--no-x``)."""
    flags = {a.split("=", 1)[0] for a in argv if a.startswith("--")}
    return {o.name for o in options.SETTINGS
            if o.flag in flags or (isinstance(o, options.Flag) and "--no-" + o.flag[2:] in flags)}


def _literal(text):
    """A help text as argparse prints it: its own % signs doubled (argparse %-formats help)."""
    return text.replace("%", "%%")


# The preview's own options (not settings of the solve).
RESOLUTION = options.Number("resolution", "--resolution", 480, 16, 16384, "Resolution", "", unit="pixels", integer=True)
SAMPLES = options.Number("samples", "--samples", 16, 1, 65536, "Samples", "", integer=True)
# With live lamps the preview renders the lamps' light and a bounce, denoised: the main job's picture at 16 samples
# is as close to Cycles as at 64, in a quarter of the render (benchmarks/results/main_job.md).
LIVE_SAMPLES = 16


def checked(args):
    """The arguments with every setting checked against its range (ValueError naming it), and
    relighting's own options refused without --relight (a solve would ignore them)."""
    if (args.strength or args.colour) and not args.relight:
        given = "--strength" if args.strength else "--colour"
        raise ValueError(f"{given} changes a light for --relight, which recombines a solved file's per-light results; "
                         "add --relight --open FILE.blend (a solve takes the lights from the scene)")
    args.samples_given = args.samples is not None
    if not args.samples_given:
        args.samples = default_samples(args)
    for option in (*options.SETTINGS, RESOLUTION, SAMPLES):
        setattr(args, option.name, option.check(getattr(args, option.name)))
    return args



def default_samples(args):
    """The preview's samples where --samples is not given: more for a live preview (a Monte Carlo render)."""
    return LIVE_SAMPLES if args.live_lamps and args.output == "TEXTURED" else SAMPLES.default
