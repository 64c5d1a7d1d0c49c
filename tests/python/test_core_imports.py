"""core/'s modules import one another without a cycle, counted statically from the AST with
every import, a function's deferred ones included (a deferred import hides a cycle; it does
not remove it)."""
import ast
import os

CORE = os.path.join(os.path.dirname(__file__), "..", "..", "addon", "canopy_ao", "core")


def _module_name(path, root=CORE):
    rel = os.path.relpath(path, root)[:-3].replace(os.sep, ".")
    return rel[:-len(".__init__")] if rel.endswith("__init__") else rel


def _resolve(module, level, name, is_package):
    """core-relative dotted name of a relative import from ``module`` (None: outside core)."""
    parts = module.split(".") if module != "__init__" else []
    if not is_package:
        parts = parts[:-1]
    up = level - 1
    if up > len(parts):
        return None
    base = parts[:len(parts) - up] if up else parts
    return ".".join(base + ([name] if name else []))


def import_graph(root=CORE):
    """{module: set of core modules it imports}, module names relative to core ("" = core)."""
    modules = {}
    for d, _dirs, files in os.walk(root):
        for f in files:
            if f.endswith(".py"):
                path = os.path.join(d, f)
                name = _module_name(path, root)
                modules["" if name == "__init__" else name] = (path, f == "__init__.py")
    graph = {}
    for name, (path, is_package) in modules.items():
        with open(path, encoding="utf-8") as fh:
            tree = ast.parse(fh.read(), path)
        deps = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.level:
                target = _resolve(name or "__init__", node.level, node.module, is_package)
                if target is None:
                    continue
                for alias in node.names:  # "from . import cost" names a module
                    sub = f"{target}.{alias.name}" if target else alias.name
                    deps.add(sub if sub in modules else target)
            elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith(
                    "canopy_ao.core"):
                deps.add(node.module[len("canopy_ao.core."):])
        # Importing a.b runs package a's __init__ first: an edge to it as well.
        deps |= {".".join(d.split(".")[:k]) for d in deps for k in range(1, d.count(".") + 1)}
        graph[name] = {d for d in deps if d in modules and d != name}
    return graph


def find_cycle(graph):
    """One import cycle as a list of modules, or None."""
    state = {}

    def visit(m, stack):
        state[m] = 1
        stack.append(m)
        for d in sorted(graph.get(m, ())):
            if d.startswith(m + ".") or m == "":  # a package importing its own parts
                continue
            if state.get(d) == 1:
                return stack[stack.index(d):] + [d]
            if d not in state:
                got = visit(d, stack)
                if got:
                    return got
        stack.pop()
        state[m] = 2
        return None

    for m in sorted(graph):
        if m not in state:
            got = visit(m, [])
            if got:
                return got
    return None


def test_the_graph_is_read():
    graph = import_graph()
    # Sanity: known edges are seen (a graph read wrong finds no cycle either).
    assert "lighting" in graph["ladder"] and "native" in graph["lighting"]
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]


def test_no_import_cycle_in_core():
    cycle = find_cycle(import_graph())
    assert cycle is None, " -> ".join(cycle)
