"""fractalc's import graph: circles among its modules, and the imports
deferred into functions that close one (docs/architecture.md):

    python benchmarks/import_graph.py [CHECKOUT]

An import inside a function (or a class body) is deferred; one at module
level, or in a module-level `if`/`try`, is not. A deferred import closes a
circle when the module it imports reaches the importer again.
"""
import ast
import sys
from pathlib import Path

root = (Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent.parent) / "fractalc"

def module_name(path):
    rel = path.relative_to(root.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)

def targets(node, here, is_package):
    """fractalc modules an import statement names."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names if a.name.startswith("fractalc")]
    if node.level:
        base = here.split(".") if is_package else here.split(".")[:-1]
        base = base[:len(base) - node.level + 1]
        prefix = ".".join(base + ([node.module] if node.module else []))
    else:
        prefix = node.module or ""
    if not prefix.startswith("fractalc"):
        return []
    out = []
    for a in node.names:
        candidate = f"{prefix}.{a.name}"
        out.append(candidate if candidate in modules else prefix)
    return out

files = sorted(root.rglob("*.py"))
modules = {module_name(p): p for p in files}
top, deferred = {m: set() for m in modules}, {m: set() for m in modules}
for m, p in modules.items():
    tree = ast.parse(p.read_text())
    is_package = p.name == "__init__.py"
    toplevel = set()
    for node in tree.body:
        for sub in ast.walk(node) if isinstance(node, (ast.If, ast.Try)) else [node]:
            if isinstance(sub, (ast.Import, ast.ImportFrom)):
                toplevel.add(id(sub))
                top[m].update(t for t in targets(sub, m, is_package) if t in modules and t != m)
    for node in ast.walk(tree):
        if isinstance(node, (ast.Import, ast.ImportFrom)) and id(node) not in toplevel:
            deferred[m].update(t for t in targets(node, m, is_package) if t in modules and t != m)

def reaches(graph, start, goal):
    seen, todo = set(), [start]
    while todo:
        n = todo.pop()
        if n == goal:
            return True
        if n not in seen:
            seen.add(n); todo.extend(graph[n])
    return False

both = {m: top[m] | deferred[m] for m in modules}
def circles(graph):
    """Strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]
    sys.setrecursionlimit(10000)
    def visit(v):
        index[v] = low[v] = counter[0]; counter[0] += 1; stack.append(v); on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w); low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop(); on.discard(w); comp.append(w)
                if w == v: break
            if len(comp) > 1: out.append(sorted(comp))
    for v in graph:
        if v not in index: visit(v)
    return out

print("circles of module-level imports:", circles(top) or "none")
print("circles counting deferred imports:", circles(both) or "none")
count = sum(len(d) for d in deferred.values())
breaking = [(m, t) for m in modules for t in sorted(deferred[m]) if reaches(both, t, m)]
print(f"deferred imports of fractalc modules: {count} (module -> module pairs)")
print(f"  of them closing a circle (the imported module reaches the importer): {len(breaking)}")
for m, t in breaking:
    print(f"    {m} -> {t}")
