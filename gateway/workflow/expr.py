"""Expressions and templates in workflow files: ``${customer.count}``, ``"Hello ${name}"``, ``if: "n > 2"``.

Why: data passes between steps (a step ``save``s its output under a name, later steps read it), and
branches test that data. Workflow authors are domain experts, so expressions must be safe (no
imports, no attribute access to Python internals) and small: we use ``simpleeval`` rather than
``eval``. Dict keys can be read with dots (``rules.actions``) as well as with brackets.
"""

from __future__ import annotations

from typing import Any, Mapping

from simpleeval import DEFAULT_FUNCTIONS, EvalWithCompoundTypes, InvalidExpression

FUNCTIONS = {
    **{k: v for k, v in DEFAULT_FUNCTIONS.items() if k not in ("rand", "randint")},
    "len": len, "min": min, "max": max, "abs": abs, "round": round, "bool": bool,
    "any": any, "all": all, "sorted": sorted,
}



class ExpressionError(ValueError):
    """An expression could not be parsed or evaluated; ``expression`` says which."""

    def __init__(self, expression: str, message: str) -> None:
        super().__init__(f"expression {expression!r}: {message}")
        self.expression = expression
        self.message = message


def evaluate(expression: str, names: Mapping[str, Any]) -> Any:
    """Evaluate one expression against the run's data (``names``)."""
    evaluator = EvalWithCompoundTypes(names=dict(names), functions=FUNCTIONS)
    try:
        return evaluator.eval(expression)
    except InvalidExpression as exc:
        raise ExpressionError(expression, str(exc)) from None
    except SyntaxError as exc:
        raise ExpressionError(expression, f"syntax error: {exc.msg}") from None
    except (TypeError, ValueError, KeyError, IndexError, ZeroDivisionError, AttributeError) as exc:
        raise ExpressionError(expression, f"{type(exc).__name__}: {exc}") from None


def check_syntax(expression: str) -> str | None:
    """Parse without evaluating; returns an error message or None (used by validation)."""
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
