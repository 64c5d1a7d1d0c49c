"""A rung is asked, never named: outside core/rungs/ no add-on code compares a method with a
rung's name (``method == "hybrid"``, ``method in ("raytrace", "grid")``), so adding a rung is
its file and its registry line (docs/DESIGN.md, 'Architecture'). Static, from the AST."""
import ast
import os
import sys

ADDON = os.path.join(os.path.dirname(__file__), "..", "..", "addon")
PACKAGE = os.path.join(ADDON, "canopy_ao")
sys.path.insert(0, os.path.abspath(ADDON))

from canopy_ao.core.rungs import base as rungs  # noqa: E402
from canopy_ao.core.rungs import registry  # noqa: E402, F401  (fills the ladder)

ALLOWED = (os.path.join(PACKAGE, "core", "rungs"),)


def _names_in(node):
    """Rung-name string constants in a comparison operand (a constant, or a tuple, list or set
    of them, or a concatenation of such)."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return [node.value]
    if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
        return [v for e in node.elts for v in _names_in(e)]
    if isinstance(node, ast.BinOp):
        return _names_in(node.left) + _names_in(node.right)
    return []


# "auto" is also the command line's word for an optional number's None and an image's
# default dtype: compared with a method ("method" in the other operand's text) it is the rung.
AMBIGUOUS = {"auto"}


def name_comparisons(source, names, filename="<source>"):
    """(line, text) of each Compare whose operands hold one of ``names`` as a string, and of
    each tuple, list or set of two or more of them bound to a name (``RAY_METHODS = ("raytrace",
    "hybrid")``, compared elsewhere as ``method in RAY_METHODS``)."""
    found = []
    for node in ast.walk(ast.parse(source, filename)):
        if isinstance(node, ast.Compare):
            text = ast.get_source_segment(source, node)
            operands = [node.left, *node.comparators]
            for op in operands:
                hit = [v for v in _names_in(op) if v in names]
                others = " ".join(ast.get_source_segment(source, o) for o in operands
                                  if o is not op)
                if any(v not in AMBIGUOUS or "method" in others for v in hit):
                    found.append((node.lineno, text))
                    break
        elif isinstance(node, (ast.Assign, ast.AnnAssign)) and isinstance(
                node.value, (ast.Tuple, ast.List, ast.Set)):
            values = _names_in(node.value)
            if len(values) >= 2 and all(v in names for v in values):
                found.append((node.lineno, ast.get_source_segment(source, node)))
    return sorted(found)


def test_the_scan_finds_comparisons():
    names = {"hybrid", "raytrace", "grid"}
    src = ('if m == "hybrid": pass\n'
           'x = m in ("raytrace", "grid")\n'
           'y = m not in {"grid"} | s\n'
           'z = m in TAU + ("raytrace",)\n'
           'RAYS = ("raytrace", "hybrid")\n'
           'a = s.method != "auto"\n'
           'ok = m == "GRASS" or f(method="grid") or dtype == "auto" or ("grid", 2)\n')
    assert sorted(line for line, _ in name_comparisons(src, names | {"auto"})) == [1, 2, 3, 4, 5, 6]


def test_no_rung_name_is_compared_outside_the_rungs():
    names = set(rungs.names())
    assert {"auto", "raytrace", "hybrid", "sphere"} <= names
    found = []
    for root, _dirs, files in os.walk(PACKAGE):
        if root.startswith(ALLOWED):
            continue
        for f in files:
            if f.endswith(".py"):
                path = os.path.join(root, f)
                with open(path, encoding="utf-8") as fh:
                    src = fh.read()
                found += [f"{os.path.relpath(path, PACKAGE)}:{line}: {text}"
                          for line, text in name_comparisons(src, names, path)]
    assert not found, "ask the rung (core/rungs/base.py) instead:\n" + "\n".join(found)
