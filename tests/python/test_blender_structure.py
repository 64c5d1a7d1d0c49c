"""blender/'s structure (docs/DESIGN.md, 'Architecture'), read from the source without bpy: its
modules import one another in one direction (no cycle, lazy imports inside functions
included), and the bake job never asks which kind of target it bakes (targets.Target's
interface does: vertex_target.py, texel_target.py)."""
import ast
import os

import pytest

BLENDER = os.path.join(os.path.dirname(__file__), "..", "..", "addon", "canopy_ao", "blender")


def _tree(name):
    with open(os.path.join(BLENDER, name + ".py"), encoding="utf-8") as f:
        return ast.parse(f.read(), name + ".py")


def _modules():
    return sorted(f[:-3] for f in os.listdir(BLENDER) if f.endswith(".py"))


def imports_of(tree, modules):
    """The sibling modules a module's source imports (``from . import x``, ``from .x import
    y``), at any depth: a lazy import inside a function is an edge too."""
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level == 1:
            if node.module:
                found.add(node.module.split(".")[0])
            else:
                found.update(a.name for a in node.names)
    return found & set(modules)


def cycles(graph):
    """Every strongly connected set of more than one module (or a module importing itself),
    each sorted (Tarjan's algorithm)."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            part = []
            while True:
                w = stack.pop()
                on.discard(w)
                part.append(w)
                if w == v:
                    break
            if len(part) > 1 or v in graph.get(v, ()):
                out.append(sorted(part))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(out)


def test_the_cycle_finder_finds_cycles():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"a"}}) == [["a"]]
    assert cycles({"a": {"b"}, "b": set(), "c": {"a", "b"}}) == []
    lazy = ast.parse("def f():\n    from .job import BakeJob\nfrom . import live, bpy_thing\n")
    assert imports_of(lazy, ["job", "live", "frames"]) == {"job", "live"}


def test_blender_modules_import_in_one_direction():
    modules = _modules()
    graph = {m: imports_of(_tree(m), modules) for m in modules}
    assert {"job", "live", "frames", "operators", "loop", "targets"} <= set(graph)
    assert cycles(graph) == []
    # The bake's layers: operators, frames, live -> job -> live_session -> loop -> the target
    # kinds -> targets.
    top = {"operators", "frames", "live"}
    assert not top & (graph["job"] | graph["live_session"])
    assert not (top | {"job", "live_session"}) & graph["loop"]
    for kind in ("vertex_target", "texel_target", "targets"):
        assert not (top | {"job", "live_session", "loop"}) & graph[kind], kind


# What a switch on the kind of target reads: the Output option, a target's kind, the kinds'
# names and classes.
KIND_WORDS = {"vertex", "texel"}
KIND_CLASSES = {"VertexTarget", "TexelTarget"}


def _reads_kind(node):
    """node is a target's ``.kind`` or an options' ``["mode"]``."""
    return (isinstance(node, ast.Attribute) and node.attr == "kind") or (
        isinstance(node, ast.Subscript) and isinstance(node.slice, ast.Constant)
        and node.slice.value == "mode")


def kind_switches(tree):
    """(line, what) of each place the source asks which kind of target it has: a kind's name
    as a string, a target class by name, isinstance, or a comparison, condition or match on
    ``.kind`` or ``["mode"]`` (a kind's own attributes, ``kind.per_vertex``, are its
    interface, not a switch)."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) \
                and node.value.lower() in KIND_WORDS:
            found.append((node.lineno, repr(node.value)))
        elif isinstance(node, ast.Name) and node.id in KIND_CLASSES | {"isinstance"}:
            found.append((node.lineno, node.id))
        elif isinstance(node, ast.Attribute) and node.attr in KIND_CLASSES:
            found.append((node.lineno, node.attr))
        tested = []
        if isinstance(node, ast.Compare):
            tested = [node.left, *node.comparators]
        elif isinstance(node, (ast.If, ast.IfExp, ast.While)):
            tested = [node.test]
        elif isinstance(node, ast.BoolOp):
            tested = node.values
        elif isinstance(node, ast.Match):
            tested = [node.subject]
        found.extend((n.lineno, "a test on " + ast.unparse(n)) for n in tested
                     if _reads_kind(n))
    return sorted(set(found))


@pytest.mark.parametrize("source", [
    'if opts["mode"] == "VERTEX":\n    pass\n',
    'x = a if t.kind == "texel" else b\n',
    'ok = all(t.kind != k for t in ts)\n',
    'x = VertexTarget(it)\n',
    'x = isinstance(t, targets.TexelTarget)\n',
    'rep["attribute"] = o["attribute"] if o["mode"] == m else None\n',
    'x = y and t.kind\n',
    'match o["mode"]:\n    case _:\n        pass\n',
])
def test_the_switch_finder_finds_switches(source):
    assert kind_switches(ast.parse(source))


def test_the_switch_finder_lets_the_interface_be():
    assert kind_switches(ast.parse('kind = KINDS[opts["mode"]]\nok = kind.per_vertex and a\n'
                                   'rep["mode"] = opts["mode"].lower()\n')) == []


def test_the_job_does_not_branch_on_the_kind_of_target():
    assert kind_switches(_tree("job")) == []
