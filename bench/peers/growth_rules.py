"""Generated enterprise-size rule sets for the growth benchmark (and the big-set tests).

Why generated: real pricing/eligibility/routing tables run to thousands of rules of a few shapes.
Rule ``i`` has one of five shapes (``i % 5``) with parameters derived from ``i``, so any size is
reproducible and every engine (DRL for the gateway, durable_rules' Python DSL, drools-jpy's AST)
can be given the same rules. :func:`expected_firings` evaluates the rules in plain Python, so each
peer can be checked to fire exactly the rules it should.

Shapes: numeric range (an Order's amount in a band, per category), string equality (a Customer's
tier and region), a 2-pattern join (Customer -> Order), a 3-pattern join (Customer -> Order ->
Product) and an accumulate (sum of a customer's order amounts in a category). Like a real pricing or
eligibility table, every pattern leads with an equality Drools can hash (category, region, tier),
and constants are drawn independently, so rules share a first pattern with a few dozen others, not
thousands, and five facts match about one rule in two hundred.

No dependencies: the peers import this from their own virtualenvs.
"""

from __future__ import annotations

import hashlib
from typing import Any

PACKAGE = "org.printeps.growth"
RULES_PER_FILE = 500
KINDS = ("range", "equality", "join2", "join3", "accumulate")
TIERS = ("gold", "silver", "bronze", "basic")
REGIONS = 40
CATEGORIES = 40
MAX_AMOUNT = 10_000
BAND = 400

TYPES_DRL = f"""package {PACKAGE};
import org.printeps.gateway.Actions;
global Actions actions;

declare Customer
    id: String
    tier: String
    region: String
    age: int
end

declare Order
    id: String
    customer: String
    amount: double
    quantity: int
    category: String
end

declare Product
    id: String
    category: String
    price: double
end
"""


def kind(i: int) -> str:
    return KINDS[i % len(KINDS)]


def _draw(i: int, field: str, n: int) -> int:
    """A reproducible pseudo-random number in [0, n) for field ``field`` of rule ``i`` (independent
    between fields, so combinations of constants spread like a real table's)."""
    return int.from_bytes(hashlib.blake2b(f"{field}:{i}".encode(), digest_size=8).digest(), "big") % n


def params(i: int) -> dict[str, Any]:
    """The constants of rule ``i`` (its shape decides which ones it uses)."""
    return {
        "lo": float(_draw(i, "lo", MAX_AMOUNT)),
        "q": _draw(i, "q", 5),
        "tier": TIERS[_draw(i, "tier", len(TIERS))],
        "region": f"r{_draw(i, 'region', REGIONS)}",
        "amount": float(_draw(i, "amount", MAX_AMOUNT)),
        "age": 18 + _draw(i, "age", 50),
        "category": f"cat{_draw(i, 'category', CATEGORIES)}",
        "price": float(5 + _draw(i, "price", 40)),
        "total": float(_draw(i, "total", 2 * MAX_AMOUNT)),
    }


def rule_name(i: int) -> str:
    return f"r{i:05d} {kind(i)}"


def rule_drl(i: int, variant: int = 0) -> str:
    """One rule in DRL. ``variant`` shifts its constants (a one-rule edit in the bench)."""
    p = params(i + variant * 7919)
    k = kind(i)
    name = rule_name(i)
    if k == "range":
        when = (f'    $o: Order(category == "{p["category"]}", amount >= {p["lo"]}, amount < {p["lo"] + BAND}, '
                f"quantity >= {p['q']})")
    elif k == "equality":
        when = f'    $c: Customer(tier == "{p["tier"]}", region == "{p["region"]}")'
    elif k == "join2":
        when = (f'    $c: Customer(tier == "{p["tier"]}", region == "{p["region"]}")\n'
                f'    $o: Order(customer == $c.id, category == "{p["category"]}", amount > {p["amount"]})')
    elif k == "join3":
        when = (f'    $c: Customer(region == "{p["region"]}", age > {p["age"]})\n'
                f'    $o: Order(customer == $c.id, category == "{p["category"]}")\n'
                f"    Product(category == $o.category, price < {p['price']})")
    else:
        when = (f'    $c: Customer(region == "{p["region"]}", tier == "{p["tier"]}")\n'
                f'    accumulate(Order(customer == $c.id, category == "{p["category"]}", $a: amount); '
                f"$t: sum($a); $t > {p['total']})")
    return f'rule "{name}"\nwhen\n{when}\nthen\n    actions.say("bot", "{name}");\nend\n'


def drl_files(n: int, variants: dict[int, int] | None = None, examples: bool = False) -> dict[str, str]:
    """A rule set of ``n`` rules: ``types.drl`` and ``rules_NNN.drl`` files of 500 rules each, and
    with ``examples`` an ``examples.json`` of five requests (not the ones the bench measures)."""
    variants = variants or {}
    files = {"types.drl": TYPES_DRL}
    if examples:
        import json

        files["examples.json"] = json.dumps([{"name": f"example {k}", "facts": sample_facts(1000 + k)} for k in range(5)])
    for start in range(0, n, RULES_PER_FILE):
        body = "\n".join(rule_drl(i, variants.get(i, 0)) for i in range(start, min(n, start + RULES_PER_FILE)))
        files[f"rules_{start // RULES_PER_FILE:03d}.drl"] = f"package {PACKAGE};\n\n{body}"
    return files


def sample_facts(k: int = 0) -> list[dict[str, Any]]:
    """Five facts (2 customers, 2 orders, 1 product); ``k`` varies them from request to request."""
    return [
        {"type": "Customer", "id": "c1", "tier": TIERS[k % 4], "region": f"r{(3 * k) % REGIONS}", "age": 30 + k % 30},
        {"type": "Customer", "id": "c2", "tier": TIERS[(k + 1) % 4], "region": f"r{(3 * k + 7) % REGIONS}", "age": 55},
        {"type": "Order", "id": "o1", "customer": "c1", "amount": float((3701 * k + 1234) % MAX_AMOUNT),
         "quantity": 1 + k % 6, "category": f"cat{k % CATEGORIES}"},
        {"type": "Order", "id": "o2", "customer": "c2", "amount": float((1103 * k + 6789) % MAX_AMOUNT), "quantity": 3,
         "category": f"cat{(k + 4) % CATEGORIES}"},
        {"type": "Product", "id": "p1", "category": f"cat{k % CATEGORIES}", "price": float(10 + k % 30)},
    ]


def expected_firings(n: int, facts: list[dict[str, Any]], variants: dict[int, int] | None = None) -> dict[str, int]:
    """How often each of the ``n`` rules fires on ``facts`` (the Drools semantics, in Python)."""
    variants = variants or {}
    customers = [f for f in facts if f["type"] == "Customer"]
    orders = [f for f in facts if f["type"] == "Order"]
    products = [f for f in facts if f["type"] == "Product"]
    out: dict[str, int] = {}
    for i in range(n):
        p = params(i + variants.get(i, 0) * 7919)
        k = kind(i)
        if k == "range":
            count = sum(1 for o in orders if o["category"] == p["category"] and p["lo"] <= o["amount"] < p["lo"] + BAND
                        and o["quantity"] >= p["q"])
        elif k == "equality":
            count = sum(1 for c in customers if c["tier"] == p["tier"] and c["region"] == p["region"])
        elif k == "join2":
            count = sum(1 for c in customers if c["tier"] == p["tier"] and c["region"] == p["region"]
                        for o in orders if o["customer"] == c["id"] and o["category"] == p["category"]
                        and o["amount"] > p["amount"])
        elif k == "join3":
            count = sum(1 for c in customers if c["region"] == p["region"] and c["age"] > p["age"]
                        for o in orders if o["customer"] == c["id"] and o["category"] == p["category"]
                        for pr in products if pr["category"] == o["category"] and pr["price"] < p["price"])
        else:
            count = sum(1 for c in customers if c["region"] == p["region"] and c["tier"] == p["tier"]
                        and sum(o["amount"] for o in orders if o["customer"] == c["id"]
                                and o["category"] == p["category"]) > p["total"])
        if count:
            out[rule_name(i)] = count
    return out
