"""docs/DESIGN.md's architecture map ('Architecture') names every module of the add-on and every
public header of the native core, and nothing that does not exist: a new module fails this test
with the row to add, so the map stays the code as it is."""
import glob
import os
import re

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
DESIGN = os.path.join(REPO, "docs", "DESIGN.md")
ROOTS = {"addon/canopy_ao/": "**/*.py", "native/include/canopy_ao/": "*.h"}


def section(text, title):
    start = text.index(f"\n## {title}\n")
    end = text.find("\n## ", start + 1)
    return text[start:end if end >= 0 else len(text)]


def map_tables(text):
    """{root: [names]} from the section's tables: a table's header cell names the root
    (`addon/canopy_ao/`), each row's first cell one path under it."""
    tables, root = {}, None
    for line in section(text, "Architecture").splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")] if line.startswith("|") \
            else None
        if cells is None:
            root = None
            continue
        head = re.fullmatch(r"`([^`]+/)`", cells[0])
        if head and head.group(1) in ROOTS:
            root = head.group(1)
            tables[root] = []
        elif root and not set(cells[0]) <= set("-: "):
            tables[root] += re.findall(r"`([^`]+)`", cells[0])
    return tables


def on_disk(root):
    base = os.path.join(REPO, root)
    return sorted(os.path.relpath(p, base).replace(os.sep, "/")
                  for p in glob.glob(os.path.join(base, ROOTS[root]), recursive=True)
                  if "__pycache__" not in p)


def test_the_map_has_both_tables():
    with open(DESIGN, encoding="utf-8") as f:
        tables = map_tables(f.read())
    assert set(tables) == set(ROOTS), sorted(tables)
    assert all(len(v) >= 10 for v in tables.values()), {k: len(v) for k, v in tables.items()}


def test_every_module_is_in_the_map_and_every_row_exists():
    with open(DESIGN, encoding="utf-8") as f:
        tables = map_tables(f.read())
    problems = []
    for root in ROOTS:
        listed, files = tables.get(root, []), on_disk(root)
        dupes = sorted({n for n in listed if listed.count(n) > 1})
        missing = [n for n in files if n not in listed]
        stale = [n for n in listed if n not in files]
        problems += [f"{root}{n}: listed twice" for n in dupes]
        problems += [f"{root}{n}: not in the map; add the row | `{n}` | <what it holds> |"
                     for n in missing]
        problems += [f"{root}{n}: in the map but not on disk; remove its row" for n in stale]
    assert not problems, "docs/DESIGN.md, 'Architecture':\n" + "\n".join(problems)


def test_the_parser_reads_a_row_and_would_name_a_missing_one():
    """The test above can fail: a map without one row names that module."""
    text = ("\n## Architecture\n\n| `addon/canopy_ao/` | what |\n|---|---|\n"
            "| `cli.py` | the command line |\n\n| `native/include/canopy_ao/` | what |\n"
            "|---|---|\n| `geometry.h` | types |\n\n## Next\n")
    tables = map_tables(text)
    assert tables == {"addon/canopy_ao/": ["cli.py"], "native/include/canopy_ao/": ["geometry.h"]}
    assert "__init__.py" in on_disk("addon/canopy_ao/")
    assert "__init__.py" not in tables["addon/canopy_ao/"]
