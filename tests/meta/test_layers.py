"""The gateway's layers, checked from its source (``ast``): imports only go down, and never in a circle.

Why: a newcomer should be able to hold the package in their head (issue 27). The layers, bottom to
top, are declared once in :data:`LAYERS` (docs/architecture.md draws them); a module may import
from its own layer and the layers below it, never from a layer above. Every import counts, also
one inside a function (an import moved into a function to dodge a circle is still the circle), but
not one under ``if TYPE_CHECKING:`` (never run). Three more rules:

- no import cycle between modules (a circle hides which module is the lower one);
- every ``gateway.*`` import names a module of this tree: after a move, a stale path would still
  import through the editable install of another checkout, and only fail on someone else's machine;
- the package root keeps at most :data:`MAX_ROOT_MODULES` modules (the entry points, the
  composition root and the settings); everything else belongs to a package.
"""

from __future__ import annotations

import ast
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

# Bottom to top. A module belongs to the layer of the longest prefix that names it.
LAYERS: list[tuple[str, tuple[str, ...]]] = [
    ("settings", ("gateway", "gateway.config")),
    ("base", ("gateway.base",)),
    ("data", ("gateway.rdf", "gateway.store", "gateway.ros.convert")),
    ("engines", ("gateway.engine", "gateway.stream", "gateway.ontology", "gateway.dialogue")),
    ("workflows", ("gateway.workflow",)),
    ("runtime", ("gateway.runtime",)),
    ("interfaces", ("gateway.api", "gateway.workbench", "gateway.ros")),
    ("composition root", ("gateway.app",)),
    ("entry points", ("gateway.serve", "gateway.worker", "gateway.demo", "gateway.ros_launch", "gateway.cli")),
]
MAX_ROOT_MODULES = 8


def modules_of(root: Path, package: str = "gateway") -> dict[str, Path]:
    """Every module of ``package`` under ``root``, by dotted name (a package by its ``__init__``)."""
    found = {}
    for path in sorted((root / package).rglob("*.py")):
        parts = list(path.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        found[".".join(parts)] = path
    return found


def _under_type_checking(node: ast.If) -> bool:
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _import_nodes(tree: ast.AST):
    """Import statements that run (those under ``if TYPE_CHECKING:`` are left out)."""
    stack = [tree]
    while stack:
        node = stack.pop()
        if isinstance(node, ast.If) and _under_type_checking(node):
            stack.extend(node.orelse)
            continue
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node
        stack.extend(ast.iter_child_nodes(node))


def imports_of(name: str, path: Path, known: dict[str, Path]) -> list[tuple[str, int]]:
    """``(imported module, line)`` for each ``gateway`` import of one module. ``from p import x``
    imports the module ``p.x`` when there is one, else ``p``; a name that is no module of the tree
    is returned as it is written (the caller reports it)."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = []
    for node in _import_nodes(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        else:
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                base = ".".join(anchor + ([base] if base else []))
            targets = list(dict.fromkeys(
                f"{base}.{alias.name}" if f"{base}.{alias.name}" in known else base for alias in node.names))
        found += [(target, node.lineno) for target in targets if target == "gateway" or target.startswith("gateway.")]
    return found


def layer_of(module: str, layers: list[tuple[str, tuple[str, ...]]]) -> int:
    """The index of the layer whose longest prefix names ``module``."""
    best, best_len = -1, -1
    for index, (_, prefixes) in enumerate(layers):
        for prefix in prefixes:
            if (module == prefix or module.startswith(prefix + ".")) and len(prefix) > best_len:
                best, best_len = index, len(prefix)
    return best


def graph_of(root: Path) -> tuple[dict[str, list[tuple[str, int]]], dict[str, Path]]:
    known = modules_of(root)
    return {name: imports_of(name, path, known) for name, path in known.items()}, known


def problems(root: Path, layers: list[tuple[str, tuple[str, ...]]] = LAYERS) -> list[str]:
    """Every broken rule of the module docstring, as ``file:line: what``."""
    graph, known = graph_of(root)
    found = []
    for name, imports in sorted(graph.items()):
        where = known[name].relative_to(root)
        mine = layer_of(name, layers)
        if mine < 0:
            found.append(f"{where}: {name} is in no layer (add it to LAYERS in tests/meta/test_layers.py)")
            continue
        for target, line in imports:
            if target not in known:
                found.append(f"{where}:{line}: imports {target}, which is no module of this tree")
                continue
            theirs = layer_of(target, layers)
            if theirs > mine:
                found.append(f"{where}:{line}: {name} ({layers[mine][0]}) imports {target}, "
                             f"a layer above it ({layers[theirs][0]})")
    found += [f"import cycle: {' -> '.join(cycle + [cycle[0]])}" for cycle in cycles(graph)]
    return found


def cycles(graph: dict[str, list[tuple[str, int]]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    counter = 0

    def visit(start: str) -> None:  # iterative: no recursion limit on a deep chain
        nonlocal counter
        work = [(start, iter(sorted({t for t, _ in graph.get(start, ()) if t in graph})))]
        index[start] = low[start] = counter
        counter += 1
        stack.append(start)
        on_stack.add(start)
        while work:
            node, edges = work[-1]
            advanced = False
            for target in edges:
                if target not in index:
                    index[target] = low[target] = counter
                    counter += 1
                    stack.append(target)
                    on_stack.add(target)
                    work.append((target, iter(sorted({t for t, _ in graph.get(target, ()) if t in graph}))))
                    advanced = True
                    break
                if target in on_stack:
                    low[node] = min(low[node], index[target])
            if advanced:
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))

    for name in sorted(graph):
        if name not in index:
            visit(name)
    return sorted(found)


def root_modules(root: Path) -> list[str]:
    return sorted(p.name for p in (root / "gateway").glob("*.py"))


# --------------------------------------------------------------------------- the checker can fail


def _tree(tmp_path: Path, files: dict[str, str]) -> Path:
    for name, text in files.items():
        path = tmp_path / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(textwrap.dedent(text), encoding="utf-8")
    return tmp_path


SMALL_LAYERS = [("low", ("gateway", "gateway.low")), ("high", ("gateway.high",))]


def test_an_upward_import_is_found_also_inside_a_function(tmp_path) -> None:
    root = _tree(tmp_path, {
        "gateway/__init__.py": "",
        "gateway/high.py": "from gateway import low\n",
        "gateway/low.py": "def f():\n    from gateway.high import thing\n",
    })
    assert problems(root, SMALL_LAYERS) == [
        "gateway/low.py:2: gateway.low (low) imports gateway.high, a layer above it (high)",
        "import cycle: gateway.high -> gateway.low -> gateway.high",
    ]


def test_a_cycle_within_a_layer_and_a_stale_path_are_found(tmp_path) -> None:
    root = _tree(tmp_path, {
        "gateway/__init__.py": "",
        "gateway/low/__init__.py": "",
        "gateway/low/a.py": "from gateway.low import b\nimport gateway.gone\n",
        "gateway/low/b.py": "from . import c\n",
        "gateway/low/c.py": "from .a import x\nfrom typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from gateway.high import y\n",
        "gateway/high.py": "",
    })
    assert problems(root, SMALL_LAYERS) == [
        "gateway/low/a.py:2: imports gateway.gone, which is no module of this tree",
        "import cycle: gateway.low.a -> gateway.low.b -> gateway.low.c -> gateway.low.a",
    ]


def test_a_module_in_no_layer_is_named(tmp_path) -> None:
    root = _tree(tmp_path, {"gateway/__init__.py": "", "gateway/elsewhere.py": ""})
    assert problems(root, [("low", ("gateway",)), ("high", ("gateway.high",))]) == []
    assert problems(root, [("low", ("gateway.low",))]) == [
        "gateway/__init__.py: gateway is in no layer (add it to LAYERS in tests/meta/test_layers.py)",
        "gateway/elsewhere.py: gateway.elsewhere is in no layer (add it to LAYERS in tests/meta/test_layers.py)",
    ]


# --------------------------------------------------------------------------- the gateway itself


def test_the_gateway_imports_only_downward_and_without_cycles() -> None:
    found = problems(ROOT)
    assert not found, "\n".join(found)


def test_the_package_root_stays_small() -> None:
    modules = root_modules(ROOT)
    assert len(modules) <= MAX_ROOT_MODULES, f"gateway/ holds {len(modules)} modules: {modules}"


@pytest.mark.parametrize("layer, prefixes", LAYERS)
def test_every_declared_layer_names_modules_that_exist(layer, prefixes) -> None:
    known = modules_of(ROOT)
    for prefix in prefixes:
        assert any(m == prefix or m.startswith(prefix + ".") for m in known), f"layer {layer!r}: no module {prefix}"


#: No source file of the gateway, its Java side or the workbench's sources is longer (issue 27: a
#: file a newcomer can read; split a concept out rather than let a module grow past it).
MAX_SOURCE_LINES = 700


def long_sources(root: Path, limit: int = MAX_SOURCE_LINES) -> list[str]:
    """The source files under ``root``'s gateway/, java/src and web/src longer than ``limit`` lines."""
    found = []
    for folder, pattern in (("gateway", "*.py"), ("java/src", "*.java"), ("web/src", "*.js")):
        for path in sorted((root / folder).rglob(pattern)):
            lines = len(path.read_text(encoding="utf-8").splitlines())
            if lines > limit:
                found.append(f"{path.relative_to(root)}: {lines} lines")
    return found


def test_no_source_file_is_longer_than_the_limit() -> None:
    found = long_sources(ROOT)
    assert not found, f"longer than {MAX_SOURCE_LINES} lines: " + "; ".join(found)


def test_the_length_scan_finds_a_long_file(tmp_path) -> None:
    (tmp_path / "gateway").mkdir()
    (tmp_path / "gateway" / "long.py").write_text("x = 1\n" * 701)
    (tmp_path / "gateway" / "short.py").write_text("x = 1\n" * 700)
    assert long_sources(tmp_path) == ["gateway/long.py: 701 lines"]
