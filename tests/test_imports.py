"""No import circles among clwave's modules (docs/README.md, "Layers").

Every import counts: module-level ones and those inside functions alike.  A function-level import only
defers the loading; the two modules still need each other, so neither can be read, tested or changed
alone.  ``from pkg import name`` counts as an import of the module ``pkg.name`` where that is a module,
else of ``pkg``; a package's parents, which Python imports first, are not counted (that is the loading
mechanism, not a dependency).  Imports of other packages are left out.
"""

import ast
from pathlib import Path

import clwave

PACKAGE = Path(clwave.__file__).parent


def modules() -> dict:
    """{dotted name: path} of the package's modules."""
    found = {}
    for path in PACKAGE.rglob("*.py"):
        parts = ["clwave", *path.relative_to(PACKAGE).with_suffix("").parts]
        found[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return found


def imports(name, path, known) -> set:
    """The package's modules that module ``name`` imports, anywhere in it."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    targets = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            targets |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = package
            for _ in range(node.level - 1):
                base = base.rpartition(".")[0]
            where = (f"{base}.{node.module}" if node.module else base) if node.level else node.module
            targets |= {f"{where}.{alias.name}" if f"{where}.{alias.name}" in known else where
                        for alias in node.names}
    found = set()
    for target in targets:
        while target not in known and "." in target:  # clwave.x.y.name: the module clwave.x.y
            target = target.rpartition(".")[0]
        if target in known and target != name:
            found.add(target)
    return found


def circles(graph) -> list:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index, low, stack, on, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while not component or component[-1] != v:
                component.append(stack.pop())
                on.discard(component[-1])
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_the_circle_finder_finds_a_circle_through_a_function_level_import(tmp_path):
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": set()}
    assert circles(graph) == [["a", "b", "c"]]
    path = tmp_path / "a.py"
    path.write_text("import os\nfrom . import b\nfrom .. import top\ndef f():\n    from .c import g\n")
    assert imports("p.q.a", path, {"p", "p.q", "p.q.a", "p.q.b", "p.q.c"}) == {"p.q.b", "p.q.c", "p"}


def test_no_import_circles():
    known = modules()
    graph = {name: imports(name, path, known) for name, path in known.items()}
    assert len(graph) > 50 and graph["clwave.io.clw"] >= {"clwave.model.wavelet", "clwave.schedulers"}
    found = circles(graph)
    assert not found, "; ".join(" <-> ".join(c) for c in found)


def test_start_up_leaves_out_what_only_reconstruction_needs():
    """``import clwave`` (every command, the viewer) does not load scipy.signal, which brings scipy.stats:
    a second of start-up on 2 cores; reconstruction imports it when it runs (model/transform.py)."""
    import subprocess
    import sys

    code = "import sys, clwave; print(sorted(m for m in ('scipy.signal', 'scipy.stats') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=PACKAGE.parent).stdout
    assert out.strip() == "[]"
