"""The pages tell the truth about the repository: the README's map names every module (and no
module that is gone), every link leads to a file and heading that exist, every results file is
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


def _map_parts():
    text = README.read_text()
    assert "\n## Map of the code\n" in text and "\n`addon/`:" in text, "the README has no map of the code"
    start = text.index("## Map of the code")
    end = text.find("\n## ", start + 1)
    section = text[start:] if end < 0 else text[start:end]
    glue = section.index("\n`addon/`:")
    return section[:glue], section[glue:]


def _named_modules(part, folders):
    """The modules a part of the map names: by name, or with ``folders`` by their path too."""
    folder = r"(?:[A-Za-z_][A-Za-z0-9_]*/)?" if folders else ""
    return set(re.findall(rf"`({folder}[A-Za-z_][A-Za-z0-9_]*\.py)`", part))


def _modules(package):
    """The modules of a package as the map names them: the core's by name, the glue's by their
    path under addon/ (its layer folders; the core has its own part of the map)."""
    if package == "addon/core":
        return {p.name for p in (ROOT / package).glob("*.py")}
    return {p.relative_to(ROOT / package).as_posix() for p in (ROOT / package).rglob("*.py")
            if p.relative_to(ROOT / package).parts[0] != "core"}


@pytest.mark.parametrize("package, part", [("addon/core", 0), ("addon", 1)])
def test_the_readme_map_names_every_module_and_only_modules_that_exist(package, part):
    named = _named_modules(_map_parts()[part], folders=package != "addon/core")
    present = _modules(package)
    assert present - named == set(), f"modules of {package}/ missing from the README's map"
    assert named - present == set(), f"the README's map names modules {package}/ does not have"


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
    assert len(text.splitlines()) < 200
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
