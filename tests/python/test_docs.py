"""The documents by reader (issue #37, item 4): the README is short enough for a user deciding
and starting (≤ 300 lines); no document carries a dated or before/after narrative (history is
the git log, figures live in docs/studies/ beside the command that prints them); every relative
link and picture in them points at a file that exists."""
import glob
import os
import re

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
README = "README.md"
DOCS = [README, "docs/guide.md", "docs/DESIGN.md", "docs/PORTABILITY.md", "addon/README.md",
        "native/python/README.md",
        *sorted(glob.glob("docs/studies/*.md", root_dir=REPO))]
NARRATIVE = [README, "docs/guide.md", *sorted(glob.glob("docs/studies/*.md", root_dir=REPO))]

DATE = re.compile(r"\b20\d\d-[01]\d(-[0-3]\d)?\b")
# Wording that tells a story of changes instead of the state: "(was 0.12)", "0.12 before the
# fix", "this run's change", "until <date>", "these figures predate".
WAS_NOW = re.compile(
    r"\(was\b|\bwas \d|\bbefore (the|this|these) (fix|round|run|change|rule)|"
    r"\bthis (round|run)'s\b|\bthe rule before\b|\bpredate|\bused to\b|\bnow reads\b",
    re.I)


def read(path):
    with open(os.path.join(REPO, path), encoding="utf-8") as f:
        return f.read()


def test_the_readme_is_for_deciding_and_starting():
    lines = read(README).count("\n")
    assert lines <= 300, f"README.md has {lines} lines; move detail to docs/guide.md"
    text = read(README)
    for heading in ("## Install", "## The panel", "## The command line", "## Outputs",
                    "## Limits", "## Where the numbers are"):
        assert f"\n{heading}" in text, heading
    # The two set-up commands (.ci/run calls the second).
    assert "scripts/run_example.sh      # the main job" in text
    assert "scripts/test.sh             # every test" in text
    # Install leads with the portable zip (issue #40), then Debian's.
    assert text.index("--portable") < text.index("The zip for Debian's Blender")


@pytest.mark.parametrize("path", DOCS)
def test_no_dates(path):
    found = [m.group(0) for m in DATE.finditer(read(path))]
    assert not found, f"{path}: dates {found} (history belongs in the git log)"


@pytest.mark.parametrize("path", NARRATIVE)
def test_no_before_and_after_narrative(path):
    text = read(path)
    found = [text[max(0, m.start() - 40):m.end() + 40].replace("\n", " ")
             for m in WAS_NOW.finditer(text)]
    assert not found, f"{path}: {found}"


def test_the_narrative_check_can_fail():
    assert DATE.search("measured 2026-12-03")
    assert WAS_NOW.search("0.037 (was 0.12)") and WAS_NOW.search("0.015 before the fix")
    assert not WAS_NOW.search("nothing is written before the first write")


LINK = re.compile(r"\]\(([^)\s]+)\)")


def anchors(file):
    """GitHub's heading anchors of a Markdown file: lower case, punctuation dropped, spaces
    to hyphens."""
    with open(file, encoding="utf-8") as f:
        text = re.sub(r"^(    |```).*$", "", f.read(), flags=re.M)
    return {re.sub(r"[^\w\- ]", "", h.strip().lower()).replace(" ", "-")
            for h in re.findall(r"^#+ (.*)$", text, re.M)}


@pytest.mark.parametrize("path", DOCS)
def test_relative_links_and_pictures_exist(path):
    base = os.path.dirname(os.path.join(REPO, path))
    missing = []
    for target in LINK.findall(read(path)):
        if re.match(r"[a-z]+:", target):
            continue
        file, _, anchor = target.partition("#")
        file = os.path.normpath(os.path.join(base, file)) if file else os.path.join(REPO, path)
        if not os.path.exists(file):
            missing.append(target)
        elif anchor and file.endswith(".md") and anchor not in anchors(file):
            missing.append(target)
    assert not missing, f"{path}: links to nothing: {missing}"


def test_anchors_are_githubs():
    assert "rays-against-cycles-samples" in anchors(os.path.join(REPO, "docs", "DESIGN.md"))
    assert "the-nearfar-hybrid" in anchors(os.path.join(REPO, "docs", "DESIGN.md"))


STUDIES = sorted(glob.glob("docs/studies/*.md", root_dir=REPO))


def test_the_studies_exist_and_the_readme_lists_each():
    assert len(STUDIES) >= 4, STUDIES
    readme = read(README)
    assert all(p in readme for p in STUDIES), [p for p in STUDIES if p not in readme]


@pytest.mark.parametrize("path", STUDIES)
def test_each_study_gives_the_commands_that_print_its_figures(path):
    """Every section with a figure (a decimal number) shows a command that runs something
    under bench/, build/ or scripts/ (indented, or inline in backquotes)."""
    text = read(path)
    sections = re.split(r"\n## ", text)
    command = re.compile(r"(^    |`)(\S+ )*\S*(bench/|build/canopy_ao_bench|scripts/bench\.sh|"
                         r"\.ci/run|examples/)", re.M)
    bare = [s.splitlines()[0] for s in sections
            if re.search(r"\b\d+\.\d+\b", s) and not command.search(s)]
    assert not bare, f"{path}: sections with figures and no command: {bare}"
