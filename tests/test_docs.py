"""The pages tell the truth about the repository: the README's map names every package, the
code page every module (and no module that is gone), every link leads to a file and heading that exist, every results file is
read by a page or a benchmark, and code and pages keep the why without a tracker's history."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
PAGES = [README, ROOT / "benchmarks" / "README.md", ROOT / "sample_scenes" / "README.md",
         *sorted((ROOT / "docs").glob("*.md"))]
RESULTS = ROOT / "benchmarks" / "results"

# a tracker's history: the word issue or stop followed by a number
HISTORY = re.compile(r"\b[Ii]ssues?\s+#?\d|\b[Ss]tops?\s+\d")
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")


CODE = ROOT / "docs" / "code.md"


def _named(text, folders):
    """The modules a page names: by name, or with ``folders`` by their path under a folder too."""
    folder = r"(?:[A-Za-z_][A-Za-z0-9_]*/)?" if folders else ""
    return set(re.findall(rf"`({folder}[A-Za-z_][A-Za-z0-9_]*\.py)`", text))


def _section(text, start, end=None):
    i = text.index(start)
    j = text.index(end, i) if end else len(text)
    return text[i:j]


def test_the_code_page_names_every_module_and_only_modules_that_exist():
    """docs/code.md's tables name every module of the core (by name, in its package's row) and of
    the glue (by its folder's row), and no module that is gone."""
    text = CODE.read_text()
    core = _section(text, "## The core, bottom up", "## The glue, by layer")
    for package in sorted(p for p in (ROOT / "addon" / "core").iterdir() if (p / "__init__.py").exists()):
        row = next(line for line in core.splitlines() if line.startswith(f"| `core/{package.name}/` |"))
        present = {p.name for p in package.glob("*.py")} - {"__init__.py"}
        assert _named(row, False) == present, package.name
    top = {p.name for p in (ROOT / "addon" / "core").glob("*.py")}
    assert _named(_section(core, "At the top of the core"), False) == top
    glue = _section(text, "## The glue, by layer", "## One solve")
    for folder in sorted(p for p in (ROOT / "addon").iterdir() if (p / "__init__.py").exists() and p.name != "core"):
        row = next(line for line in glue.splitlines() if line.startswith(f"| `{folder.name}/` |"))
        assert _named(row, False) == {p.name for p in folder.glob("*.py")} - {"__init__.py"}, folder.name


def test_the_readmes_map_names_every_package_of_the_core_and_every_folder_of_the_glue():
    text = _section(README.read_text(), "## Map of the code")
    named = set(re.findall(r"^\| `([a-z_]+)/` \|", text, flags=re.M))
    core = {p.name for p in (ROOT / "addon" / "core").iterdir() if (p / "__init__.py").exists()}
    glue = {p.name for p in (ROOT / "addon").iterdir() if (p / "__init__.py").exists()} - {"core"}
    assert named == core | glue


def test_following_one_solve_from_the_panel_to_the_colours_opens_at_most_twelve_modules():
    steps = re.findall(r"^\d+\. `([a-z_/]+\.py)`", _section(CODE.read_text(), "## One solve"), flags=re.M)
    assert 0 < len(steps) <= 12 and all((ROOT / "addon" / step).exists() for step in steps), steps


def _slug(heading):
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def _anchors(page):
    slugs, seen = set(), {}
    in_code = False
    for line in page.read_text().splitlines():
        if line.startswith("```"):
            in_code = not in_code
        if in_code or not line.startswith("#"):
            continue
        slug = _slug(line.lstrip("#"))
        n = seen.get(slug, 0)
        seen[slug] = n + 1
        slugs.add(slug if n == 0 else f"{slug}-{n}")
    return slugs


def _links(page):
    text = re.sub(r"```.*?```", "", page.read_text(), flags=re.S)
    return [m.group(1) for m in LINK.finditer(text)]


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_leads_to_a_file_and_heading_that_exist(page):
    broken = []
    for target in _links(page):
        if re.match(r"[a-z]+:", target):  # http:, https:, mailto:
            continue
        path, _, anchor = target.partition("#")
        dest = (page.parent / path).resolve() if path else page
        if not dest.exists():
            broken.append(target)
        elif anchor and dest.suffix == ".md" and anchor not in _anchors(dest):
            broken.append(target)
    assert broken == [], f"{page.name}: links to nothing"


def test_every_results_file_is_read_by_a_page_or_a_benchmark():
    files = [*ROOT.glob("*.md")] + [p for d in ("addon", "benchmarks", "docs", "sample_scenes", "tests", "tools")
                                    for p in (ROOT / d).rglob("*") if p.suffix in (".md", ".py")]
    texts = {p: p.read_text(errors="replace") for p in files}
    unread = [f.name for f in sorted(RESULTS.iterdir())
              if not any(f.name in text for p, text in texts.items() if p != f)]
    assert unread == [], "results files that no page or benchmark names"


def test_the_readme_is_a_page_with_the_two_commands_and_the_main_jobs_picture():
    text = README.read_text()
    assert len(text.splitlines()) <= 150
    assert "\n    bash tools/run.sh --scene cornell\n" in text
    assert "\n    bash tools/test.sh\n" in text
    assert "bash tools/test.sh" in (ROOT / ".ci" / "run").read_text()
    pictures = [t for t in _links(README) if t.endswith(".png")]
    assert pictures and all((ROOT / t).stat().st_size < 300_000 for t in pictures)


def test_code_and_pages_keep_the_why_not_the_trackers_history():
    files = [p for d in ("addon", "tests", "benchmarks", "tools", "sample_scenes")
             for p in (ROOT / d).rglob("*") if p.suffix in (".py", ".sh")]
    # robustness.md is assembled from the helpers' reports; the results' titles are the scripts'
    files += [p for p in PAGES if p.name != "robustness.md"]
    files += sorted(RESULTS.glob("*.md"))
    found = [f"{p.relative_to(ROOT)}:{i}" for p in files
             for i, line in enumerate(p.read_text(errors="replace").splitlines(), 1)
             if HISTORY.search(line)]
    assert found == []


def test_a_path_a_page_gives_relative_to_itself_is_a_file_of_the_repository():
    """The sample scenes' page cited the paper at a path outside the repository: a page names
    files the reader has, and cites papers by their title."""
    missing = []
    for page in PAGES:
        for path in re.findall(r"`(\.\.?/[^`\s]+)`", page.read_text()):
            target = (page.parent / path).resolve()
            if ROOT not in target.parents or not target.exists():
                missing.append(f"{page.relative_to(ROOT)}: {path}")
    assert missing == []
