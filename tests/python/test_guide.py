"""docs/guide.md's option tables are the parsers' options (issue #37, item 4): every option of
the command line (`cli.build_parser`) and of the batch (`canopy_ao.batch.__main__.build_parser`)
has a row, no row names an option that does not exist, and a choice list in a row is the
parser's. So `-- --help` and the guide cannot drift apart."""
import os
import re

import pytest

from canopy_ao import cli
from canopy_ao.batch import __main__ as batch_main

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
GUIDE = os.path.join(REPO, "docs", "guide.md")


def section(text, title):
    start = text.index(f"\n## {title}")
    end = text.find("\n## ", start + 1)
    return text[start:end if end >= 0 else len(text)]


def option_rows(text):
    """{flag: the row's first cell} for every table row whose first cell starts with a flag."""
    rows = {}
    for line in text.splitlines():
        m = re.match(r"\|\s*(`-[^|]*)\|", line)
        if m:
            for flag in re.findall(r"`(--?[a-z][a-z-]*)", m.group(1)):
                rows[flag] = m.group(1)
    return rows


def parser_flags(parser):
    flags = {}
    for action in parser._actions:
        for flag in action.option_strings:
            if flag not in ("-h", "--help"):
                flags[flag] = action
    return flags


def choices(action):
    """The choice list argparse shows (the CLI's enums name theirs in the metavar)."""
    if action.choices:
        return set(map(str, action.choices))
    m = isinstance(action.metavar, str) and re.fullmatch(r"\{([^}]*)\}", action.metavar)
    return set(m.group(1).split(",")) if m else None


def check(rows, flags):
    problems = [f"{f}: an option with no row in the guide" for f in flags if f not in rows]
    problems += [f"{f}: a row for an option the parser does not have" for f in rows
                 if f not in flags]
    for flag, action in flags.items():
        want = choices(action)
        got = re.search(r"\{([^}]*)\}", rows.get(flag, ""))
        if want and (not got or set(got.group(1).split(",")) != want):
            problems.append(f"{flag}: the guide's choices {got and got.group(0)} are not "
                            f"{{{','.join(sorted(want))}}}")
    return problems


@pytest.mark.parametrize("title, build, least", [
    ("The command line", lambda: cli.build_parser(), 40),
    ("Batch bakes", lambda: batch_main.build_parser(), 10)])
def test_every_option_has_its_row(title, build, least):
    with open(GUIDE, encoding="utf-8") as f:
        rows = option_rows(section(f.read(), title))
    flags = parser_flags(build())
    assert len(flags) >= least
    problems = check(rows, flags)
    assert not problems, f"docs/guide.md, '{title}':\n" + "\n".join(problems)


def test_the_check_can_fail():
    flags = parser_flags(cli.build_parser())
    rows = option_rows("| `--method {auto,sphere}` | x |\n| `--no-such-option` | y |\n")
    problems = "\n".join(check(rows, flags))
    assert "--all: an option with no row" in problems
    assert "--no-such-option: a row for an option" in problems
    assert "--method: the guide's choices {auto,sphere}" in problems
