"""Every Blender command the project documents that runs the add-on (a --python-expr naming
canopy_ao, or a --python script that imports it) carries --python-exit-code 1 before its
script: without it Blender exits 0 when the script fails, and a pipeline would take a missing
add-on for a success (tests/blender/test_cli_exit_codes.py runs the CLI ones without it)."""
import glob
import os
import re

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
DOCS = ["README.md", "addon/README.md", "bench/README.md", *glob.glob("docs/*.md", root_dir=REPO),
        *glob.glob("docs/studies/*.md", root_dir=REPO),
        *glob.glob("scripts/*.sh", root_dir=REPO), *glob.glob("examples/*.py", root_dir=REPO)]
RUNS_ADDON = re.compile(r"\bimport canopy_ao|\bfrom canopy_ao|canopy_ao\.(cli|blender|batch)")


def commands(path):
    with open(os.path.join(REPO, path), encoding="utf-8") as f:
        text = re.sub(r"\\\n\s*", " ", f.read())
    return [m.group(0) for m in re.finditer(r"blender -b[^`\n]*--python[^`\n]*", text)]


def runs_the_addon(command):
    script = re.search(r"--python (\S+\.py)", command)
    if script and os.path.isfile(os.path.join(REPO, script.group(1))):
        with open(os.path.join(REPO, script.group(1)), encoding="utf-8") as f:
            return bool(RUNS_ADDON.search(f.read()))
    expr = re.search(r"--python-expr\s+(\"[^\"]*\"|'[^']*')", command)
    return bool(expr and RUNS_ADDON.search(expr.group(1)))


@pytest.mark.parametrize("path", DOCS)
def test_documented_commands_fail_when_the_addon_is_missing(path):
    for command in commands(path):
        if not runs_the_addon(command):
            continue
        code = command.find("--python-exit-code")
        script = re.search(r"--python(-expr)?\s", command).start()
        assert 0 <= code < script, f"{path}: no --python-exit-code before the script: {command}"


def test_the_documented_commands_are_found():
    found = [c for p in DOCS for c in commands(p) if runs_the_addon(c)]
    assert len(found) >= 10, found
