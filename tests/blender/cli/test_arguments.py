"""The command line's arguments: what --help promises, and arguments that cannot work together
refused in one line before anything runs (status 2, nothing written)."""

import os
import re
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
QUICK = ["--scene", "cornell", "--error", "20", "--patch-size", "0.4", "--threads", "1"]


def _cli(args, cwd, timeout=300):
    return subprocess.run([sys.executable, "-m", "addon", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=timeout, env={**os.environ, "PYTHONPATH": ROOT})


def _help():
    """--help's text, one entry an option: {flag: its help, on one line}."""
    text = _cli(["--help"], ROOT).stdout
    entries, flag = {}, None
    for line in text[text.index("options:"):].splitlines()[1:]:
        head = re.match(r"  (-[-\w]+)", line)
        if head:
            flag = head.group(1)
            entries[flag] = line[len(head.group(0)):]
        elif flag:
            entries[flag] += " " + line.strip()
    return text, {flag: " ".join(words.split()) for flag, words in entries.items()}


def test_every_option_of_the_help_says_what_it_does_and_its_range_in_whole_numbers():
    from addon.bpy_free import options

    text, entries = _help()
    assert not re.search(r"\de[+-]?0\d", text.replace("1e-06", "")), text  # no 2.14748e+09 for a whole number
    assert "between 0 and 2147483647; default 0" in entries["--seed"]
    for option in options.SETTINGS:
        words = entries[option.flag]
        described = re.sub(r"\([^()]*(?:default|between|at least)[^()]*\)", "", words)  # (its range or default)
        assert len(re.sub(r"^\s*\S+(\s*[,|]\s*\S+)*", "", described).split()) >= 5, (option.flag, words)
    for flag in ("--resolution", "--samples"):
        assert "default" in entries[flag], entries[flag]


def test_the_help_says_the_direct_light_setting_is_the_walks_and_the_two_way_iteration_gathers():
    """The default run's method (Automatic: the two-way iteration in the main job's box) gathers
    its direct light whatever --direct-light says: the help says so beside its default."""
    _, entries = _help()
    words = entries["--direct-light"]
    assert "default shot" in words and "two-way iteration" in words and "always gathers" in words


@pytest.mark.parametrize("args", [["--strength", "Lamp=3"], ["--colour", "Lamp=1,0.8,0.6"],
                                  ["--open", "room.blend", "--strength", "Lamp=3"]])
def test_strength_or_colour_without_relight_is_refused_before_anything_runs(tmp_path, args):
    """A solve takes its lights from the scene: --strength/--colour without --relight were
    ignored while a full solve ran."""
    proc = _cli([*args, *QUICK[2:], "--no-preview", "-o", str(tmp_path / "x.blend")], str(tmp_path))
    assert proc.returncode == 2, proc.stdout[-2000:] + proc.stderr[-2000:]
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: --") and "add --relight" in lines[0], proc.stderr
    assert "patches" not in proc.stdout and os.listdir(tmp_path) == []


@pytest.mark.parametrize("preview", ["out/box.blend", "./out/../out/box.blend", "{tmp}/out/box.blend"])
def test_a_preview_naming_the_output_file_is_refused_before_the_run(tmp_path, preview):
    """--preview naming the .blend -o names (in any spelling) failed only after the solve and
    the render, naming a temporary file."""
    proc = _cli([*QUICK, "-o", "out/box.blend", "--preview", preview.format(tmp=tmp_path),
                 "--resolution", "32", "--samples", "1"], str(tmp_path))
    assert proc.returncode == 2, proc.stdout[-2000:] + proc.stderr[-2000:]
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert lines == [f"error: --preview and --output both name {tmp_path / 'out' / 'box.blend'}: "
                     "give the preview a file of its own"], proc.stderr
    assert "patches" not in proc.stdout and os.listdir(tmp_path) == []


USAGE = os.path.join(ROOT, "docs", "usage.md")


def test_the_usage_page_gives_the_command_lines_own_defaults():
    """docs/usage.md said the default colours were BOTH (TEXTURED is): the defaults it lists are
    the parser's."""
    from addon.bpy_free import options
    from addon.cli.arguments import parser

    with open(USAGE) as f:
        text = " ".join(f.read().split())
    stated = text[text.index("choices in any case), defaults:"):]
    pairs = re.findall(r"`(--[\w-]+) ([\w.]+)`", stated[:stated.index(". ")])
    assert {flag for flag, _ in pairs} >= {"--method", "--error", "--patch-size", "--colours", "--direct-light"}
    defaults = parser().parse_args([])
    by_flag = {o.flag: o for o in options.SETTINGS}
    for flag, value in pairs:
        default = getattr(defaults, by_flag[flag].name)
        assert (float(value) == default) if isinstance(by_flag[flag], options.Number) else value == default, flag


def test_the_usage_page_gives_the_exit_status_of_each_kind_of_failure():
    """docs/usage.md said nothing selected exits with 1 (it is 2, as a wrong command line): its
    table of statuses says which failures give which, and each signal's status."""
    from addon.cli.interrupt import STOPPING, status_of

    with open(USAGE) as f:
        rows = dict(re.findall(r"^\| (\d+) \| (.+) \|$", f.read(), re.M))
    assert "nothing selected" in rows["2"] and "faces have no area" in rows["2"] and "no emitter" in rows["1"]
    assert "options that cannot work together" in rows["2"]
    for signum, name in STOPPING.items():
        assert name.split()[0] in rows[str(status_of(signum))], name
