"""Expressions and templates in workflow files: ``${customer.count}``, ``"Hello ${name}"``, ``if: "n > 2"``.

Why: data passes between steps (a step ``save``s its output under a name, later steps read it), and
branches test that data. Workflow authors are domain experts, so expressions must be safe (no
imports, no attribute access to Python internals) and small: we use ``simpleeval`` rather than
``eval``. Dict keys can be read with dots (``rules.actions``) as well as with brackets.

On top of simpleeval's own limits (no dunder attributes, no imports, bounded strings and
comprehensions), no method that changes the run's data in place (``x.clear()``), and what it lets
through is bounded here too (tests/workflow/test_expr_sandbox.py
attacks it): integer results stay under :data:`MAX_INT_BITS` (``4000000 ** 4000000`` passes
simpleeval's exponent check and then computes for minutes), repeated strings and lists under
:data:`MAX_REPEATED` items in all, expressions under
:data:`MAX_EXPRESSION_LENGTH` characters and :data:`MAX_NESTING` levels, and a recursion or memory
error is an :class:`ExpressionError`, never a crash of the run.
"""

from __future__ import annotations

import ast
import math
import operator
from typing import Any, Mapping

from simpleeval import (DEFAULT_FUNCTIONS, DEFAULT_OPERATORS, EvalWithCompoundTypes, FeatureNotAvailable,
                        InvalidExpression, IterableTooLong, NumberTooHigh, safe_mult)

MAX_INT_BITS = 4096  # ~1233 digits: far beyond any count, price or distance a workflow handles
MAX_EXPRESSION_LENGTH = 4000
MAX_NESTING = 64
MAX_REPEATED = 200_000  # items made by repeating strings or lists (``"-" * 40``), in one expression

FUNCTIONS = {
    **{k: v for k, v in DEFAULT_FUNCTIONS.items() if k not in ("rand", "randint")},
    "len": len, "min": min, "max": max, "abs": abs, "round": round, "bool": bool,
    "any": any, "all": all, "sorted": sorted,
}


def _too_big(bits: float, what: str) -> NumberTooHigh:
    return NumberTooHigh(f"{what} would be a number of about {int(bits)} bits (at most {MAX_INT_BITS})")


def _power(a: Any, b: Any) -> Any:
    """``a ** b`` refused when an integer result would exceed :data:`MAX_INT_BITS`."""
    if isinstance(a, int) and isinstance(b, int) and b > 0 and abs(a) > 1:
        bits = b * math.log2(abs(a))
        if bits > MAX_INT_BITS:
            raise _too_big(bits, f"{a} ** {b}")
    return a ** b


class _Repeats:
    """``a * b`` for one evaluation: integer products bounded in bits, and the strings and lists
    made by repeating bounded in total (simpleeval bounds each to 100000, but a comprehension can
    make 10000 of them: ``[[1] * 99999 for a in [1] * 9999]`` is a billion elements)."""

    def __init__(self) -> None:
        self.left = MAX_REPEATED

    def __call__(self, a: Any, b: Any) -> Any:
        if isinstance(a, int) and isinstance(b, int) and a.bit_length() + b.bit_length() > MAX_INT_BITS:
            raise _too_big(a.bit_length() + b.bit_length(), "the product")
        result = safe_mult(a, b)
        if hasattr(result, "__len__"):
            self.left -= len(result)
            if self.left < 0:
                raise IterableTooLong(f"repeating strings or lists would make more than {MAX_REPEATED} items "
                                      "in one expression")
        return result


def _lshift(a: Any, b: Any) -> Any:
    if isinstance(a, int) and isinstance(b, int) and a.bit_length() + b > MAX_INT_BITS:
        raise _too_big(a.bit_length() + b, f"{a} << {b}")
    return operator.lshift(a, b)


# Methods that change a list, dict or set in place: an expression reads the run's data, it never
# changes it (``${saved.clear()}`` would empty a step's saved output for every later step).
MUTATING = frozenset({"append", "extend", "insert", "remove", "pop", "popitem", "clear", "update", "setdefault",
                      "sort", "reverse", "add", "discard", "intersection_update", "difference_update",
                      "symmetric_difference_update"})


class _Evaluator(EvalWithCompoundTypes):
    """simpleeval's evaluator with lists, dicts and comprehensions, minus the methods that mutate."""

    def _eval_attribute(self, node: ast.Attribute) -> Any:
        if node.attr in MUTATING:
            raise FeatureNotAvailable(f"'.{node.attr}' would change the run's data; expressions only read it "
                                      f"(a key of that name is read as x['{node.attr}'])")
        return super()._eval_attribute(node)


OPERATORS = {**DEFAULT_OPERATORS, ast.Pow: _power, ast.LShift: _lshift}  # ast.Mult: one _Repeats per evaluation



class ExpressionError(ValueError):
    """An expression could not be parsed or evaluated; ``expression`` says which."""

    def __init__(self, expression: str, message: str) -> None:
        super().__init__(f"expression {expression!r}: {message}")
        self.expression = expression
        self.message = message


def _check_shape(expression: str) -> None:
    """Refuses, before parsing, what is too long; after, what is nested too deep (both bound the
    recursion of the parser and the evaluator)."""
    if len(expression) > MAX_EXPRESSION_LENGTH:
        raise ExpressionError(expression[:60] + "…", f"too long: {len(expression)} characters "
                                                     f"(at most {MAX_EXPRESSION_LENGTH})")
    try:
        tree = ast.parse(expression.strip(), mode="eval")
    except SyntaxError as exc:
        raise ExpressionError(expression, f"syntax error: {exc.msg}") from None
    except (RecursionError, MemoryError):
        raise ExpressionError(expression, f"nested too deeply (at most {MAX_NESTING} levels)") from None
    stack = [(tree, 0)]
    while stack:
        node, depth = stack.pop()
        if depth > MAX_NESTING:
            raise ExpressionError(expression, f"nested too deeply (at most {MAX_NESTING} levels)")
        stack.extend((child, depth + 1) for child in ast.iter_child_nodes(node))


def evaluate(expression: str, names: Mapping[str, Any]) -> Any:
    """Evaluate one expression against the run's data (``names``)."""
    _check_shape(expression)
    evaluator = _Evaluator(names=dict(names), functions=FUNCTIONS, operators={**OPERATORS, ast.Mult: _Repeats()})
    try:
        return evaluator.eval(expression)
    except InvalidExpression as exc:
        raise ExpressionError(expression, str(exc)) from None
    except SyntaxError as exc:
        raise ExpressionError(expression, f"syntax error: {exc.msg}") from None
    except (TypeError, ValueError, KeyError, IndexError, ZeroDivisionError, AttributeError, OverflowError) as exc:
        raise ExpressionError(expression, f"{type(exc).__name__}: {exc}") from None
    except (RecursionError, MemoryError) as exc:
        raise ExpressionError(expression, f"too big to evaluate ({type(exc).__name__})") from None


def check_syntax(expression: str) -> str | None:
    """Parse without evaluating; returns an error message or None (used by validation)."""
    try:
        _check_shape(expression)
    except ExpressionError as exc:
        return f"{exc.message} in {expression[:200]!r}" if not exc.message.startswith("syntax error") else \
            f"syntax error in {expression!r}: {exc.message.removeprefix('syntax error: ')}"
    try:
        EvalWithCompoundTypes(functions=FUNCTIONS).parse(expression)
    except SyntaxError as exc:
        return f"syntax error in {expression!r}: {exc.msg}"
    return None


def placeholders(text: str) -> list[tuple[int, int, str]]:
    """``(start, end, expression)`` of each ``${...}`` in ``text``; braces inside may nest
    (``${[{'type': 'Robot'}]}``) and braces inside quotes do not count."""
    found: list[tuple[int, int, str]] = []
    start = text.find("${")
    while start != -1:
        depth, quote, i = 0, "", start + 1
        while i < len(text):
            ch = text[i]
            if quote:
                if ch == "\\":
                    i += 1
                elif ch == quote:
                    quote = ""
            elif ch in "'\"":
                quote = ch
            elif ch == "{":
                depth += 1
            elif ch == "}":
                depth -= 1
                if depth == 0:
                    found.append((start, i + 1, text[start + 2:i]))
                    break
            i += 1
        else:
            raise ExpressionError(text[start:], "'${' without its closing '}'")
        start = text.find("${", i + 1)
    return found


def template_expressions(value: Any) -> list[str]:
    """Every ``${...}`` expression inside a (nested) template value."""
    found: list[str] = []
    if isinstance(value, str):
        found.extend(expression for _s, _e, expression in placeholders(value))
    elif isinstance(value, Mapping):
        for item in value.values():
            found.extend(template_expressions(item))
    elif isinstance(value, (list, tuple)):
        for item in value:
            found.extend(template_expressions(item))
    return found


def render(value: Any, names: Mapping[str, Any]) -> Any:
    """Fill ``${...}`` placeholders in strings, recursively through dicts and lists.

    A string that is exactly one placeholder keeps the value's type (``"${count}"`` -> 3); a
    placeholder inside text is formatted with ``str``.
    """
    if isinstance(value, str):
        spots = placeholders(value)
        if len(spots) == 1 and spots[0][0] == 0 and spots[0][1] == len(value.rstrip()) and not value[:1].isspace():
            return evaluate(spots[0][2], names)
        out, last = [], 0
        for start, end, expression in spots:
            out.append(value[last:start])
            out.append(_text(evaluate(expression, names)))
            last = end
        return "".join(out) + value[last:]
    if isinstance(value, Mapping):
        return {k: render(v, names) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [render(v, names) for v in value]
    return value


def _text(value: Any) -> str:
    if isinstance(value, float) and value.is_integer():
        return str(int(value))
    return str(value)
