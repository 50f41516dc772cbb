"""A test-quality check over tests/ itself (a small AST scan): patterns that make a check unable to
fail stop here instead of landing.

- a comparison ``len(...) >= 0`` (or ``0 <= len(...)``), in an assert or a wait: always true;
- a fixture that returns or yields the same object twice (``return x, x``): a "two processes" test
  over one object passes whatever the second process would have done;
- ``route.fulfill`` in a browser test: the browser is answered by the test, not by the gateway.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parents[1]


def _always_true_len(node: ast.AST) -> bool:
    """``len(...) >= 0`` or ``0 <= len(...)``."""
    if not isinstance(node, ast.Compare) or len(node.ops) != 1:
        return False
    left, op, right = node.left, node.ops[0], node.comparators[0]

    def is_len(n: ast.AST) -> bool:
        return isinstance(n, ast.Call) and isinstance(n.func, ast.Name) and n.func.id == "len"

    def is_zero(n: ast.AST) -> bool:
        return isinstance(n, ast.Constant) and n.value == 0 and not isinstance(n.value, bool)

    return (isinstance(op, ast.GtE) and is_len(left) and is_zero(right)) or (
        isinstance(op, ast.LtE) and is_zero(left) and is_len(right))


def _is_fixture(func: ast.FunctionDef) -> bool:
    for deco in func.decorator_list:
        target = deco.func if isinstance(deco, ast.Call) else deco
        if isinstance(target, ast.Attribute) and target.attr == "fixture":
            return True
        if isinstance(target, ast.Name) and target.id == "fixture":
            return True
    return False


def _same_object_twice(value: ast.AST | None) -> bool:
    if not isinstance(value, ast.Tuple):
        return False
    names = [ast.dump(e) for e in value.elts if isinstance(e, (ast.Name, ast.Attribute))]
    return len(names) != len(set(names))


def _own_nodes(func: ast.FunctionDef):
    """The nodes of ``func`` outside nested functions (their returns are not the fixture's)."""
    stack = list(func.body)
    while stack:
        node = stack.pop()
        yield node
        if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            stack.extend(ast.iter_child_nodes(node))


def problems(source: str, filename: str = "<test>") -> list[str]:
    """Every pattern above in ``source``, as ``file:line: what``."""
    tree = ast.parse(source, filename)
    found = []
    for node in ast.walk(tree):
        where = f"{filename}:{getattr(node, 'lineno', 0)}"
        if _always_true_len(node):
            found.append(f"{where}: len(...) >= 0 is always true (the check cannot fail)")
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and _is_fixture(node):
            for inner in _own_nodes(node):
                if isinstance(inner, (ast.Return, ast.Yield)) and _same_object_twice(inner.value):
                    found.append(f"{filename}:{inner.lineno}: fixture '{node.name}' hands out one object twice")
        if isinstance(node, ast.Attribute) and node.attr == "fulfill":
            found.append(f"{where}: route.fulfill answers the browser in place of the real gateway")
    return found


@pytest.mark.parametrize("source, expected", [
    ("assert len(xs) >= 0\n", "always true"),
    ("wait_for(lambda: len(get()) >= 0, 30)\n", "always true"),
    ("assert 0 <= len(xs)\n", "always true"),
    ("import pytest\n@pytest.fixture\ndef two():\n    one = object()\n    return one, one\n", "one object twice"),
    ("import pytest\n@pytest.fixture(params=[1])\ndef two(request):\n    a = 1\n    yield a, a\n", "one object twice"),
    ("def test_x(page):\n    page.route('**/api/jobs', lambda route: route.fulfill(status=202))\n", "route.fulfill"),
])
def test_the_scan_finds_each_pattern(source, expected):
    found = problems(source)
    assert len(found) == 1 and expected in found[0], found


@pytest.mark.parametrize("source", [
    "assert len(xs) >= 1\n",
    "assert len(xs) > 0\n",
    "import pytest\n@pytest.fixture\ndef two():\n    a, b = object(), object()\n    return a, b\n",
    "def helper():\n    x = 1\n    return x, x\n",  # not a fixture
    "import pytest\n@pytest.fixture\ndef f():\n    def inner():\n        return 1, 1\n    return inner\n",
])
def test_the_scan_passes_sound_code(source):
    assert problems(source) == []


def test_no_test_in_the_suite_has_these_patterns():
    found = []
    for path in sorted(TESTS.rglob("*.py")):
        if path == Path(__file__).resolve():
            continue  # its own examples
        found += problems(path.read_text(), str(path.relative_to(TESTS.parent)))
    assert found == [], "\n".join(found)
