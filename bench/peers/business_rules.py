"""A second, independent generator of business rule bases (issue 30), for the growth benchmark and
the suite's random-rule-set test.

Why a second one: the first generator (growth_rules.py) has five shapes the gateway's fast paths
were tuned on; customers' rule bases look like neither. This one draws every rule's shape, its
constants and its attributes from a seeded random generator:

- ``multi``: one pattern with five constraints (an equality, a range, two thresholds);
- ``join``: two patterns joined on a bound variable (``$id : id`` ... ``applicant == $id``);
- ``count`` / ``sum`` / ``min`` / ``max``: ``Number( … ) from accumulate( Loan( applicant == $id … ), f( … ) )``;
- ``not`` / ``exists`` over a joined pattern;
- ``in``: ``region in ( "r1", "r5", "r9" )``;
- ``matches``: a regular expression on a text field;
- ``calls``: a then-part calling ``String.format`` and ``String.join`` (varargs, boxing),
  ``Math.max(long, long)`` with an int and ``Math.max(double, double)`` with an int (widening)
  (:data:`CALLS`);

and attributes: ``salience``, ``agenda-group`` with ``auto-focus``, ``no-loop``,
``lock-on-active``, ``date-effective`` (in the past, or in the future: never fires) and
``date-expires`` (in the future). :class:`BusinessRules` also evaluates the rules in plain Python
(:meth:`expected`), so a test or a bench peer can check that the engine fired exactly what the
rules say, with the texts the then-parts build.

No dependencies: the peers import this from their own virtualenvs.
"""

from __future__ import annotations

import random
import re
from dataclasses import dataclass, field
from typing import Any

PACKAGE = "org.printeps.business"
RULES_PER_FILE = 500
SHAPES = ("multi", "join", "count", "sum", "min", "max", "not", "exists", "in", "matches", "calls")
ATTRIBUTES = ("salience", "agenda-group", "no-loop", "lock-on-active", "date-effective", "date-future", "date-expires")

#: The then-part expressions of ``calls`` rules: static calls javac resolves by widening (an int
#: into ``Math.max(long, long)``, into ``max(double, double)``), boxing and variable arity
#: (``String.format``, ``String.join``), with the texts :meth:`BusinessRules._text` expects.
CALLS = (
    'String.format("%s|%d", $a.getId(), Math.max($a.getAge(), 1L))',
    'String.format("%s|%s", $a.getId(), Math.max($a.getIncome(), 0))',
    'String.join("/", $a.getId(), Integer.toString($a.getScore()), String.valueOf($a.getAge()))',
)

TYPES_DRL = f"""package {PACKAGE};
import org.printeps.gateway.Actions;
global Actions actions;

declare Applicant
    id : String
    age : int
    income : double
    score : int
    region : String
    segment : String
    email : String
end

declare Loan
    id : String
    applicant : String
    amount : double
    term : int
    purpose : String
end
"""


@dataclass
class Rule:
    """One generated rule: its shape, constants and attribute (what the model evaluates)."""

    index: int
    name: str
    shape: str
    p: dict[str, Any]
    attribute: str | None
    drl: str = ""


#: The key domains of a 1,000-rule base: regions, segments, loan purposes, mail domains.
BASE_DOMAINS = {"regions": 40, "segments": 6, "purposes": 6, "domains": 8}
#: The keys that grow with the base (loan purposes are a fixed list: home, car, ...).
SCALED_DOMAINS = ("regions", "segments", "domains")


@dataclass
class BusinessRules:
    """A reproducible rule base of ``n`` rules drawn with ``seed``. Smaller domains (regions,
    segments, purposes, mail domains) make more rules match a request.

    A domain left at ``None`` grows with the base beyond 1,000 rules (``scale_domains``): each
    region, segment and mail domain keeps about as many rules as in a 1,000-rule base. Why: a
    business base has 10,000 rules because it covers more keys (regions, products, channels),
    not because it writes ten times as many rules on the same six segments; with fixed domains a
    10,000-rule base had ~1,700 rules per segment and one 5-fact request fired 744 rules (7% of
    the base), which no pricing or eligibility base does. ``scale_domains=False`` gives the fixed
    domains of the bases measured before (docs/benchmarks.md)."""

    seed: int
    n: int
    regions: int | None = None
    segments: int | None = None
    purposes: int | None = None
    domains: int | None = None
    attribute_share: float = 0.3
    variants: dict[int, int] = field(default_factory=dict)
    scale_domains: bool = True

    def __post_init__(self) -> None:
        factor = max(1.0, self.n / 1000) if self.scale_domains else 1.0
        for name, base in BASE_DOMAINS.items():
            if getattr(self, name) is None:
                setattr(self, name, round(base * factor) if name in SCALED_DOMAINS else base)

    # ------------------------------------------------------------------ rules

    def rule(self, i: int) -> Rule:
        rng = random.Random(f"{self.seed}:{i}:{self.variants.get(i, 0)}")
        shape = SHAPES[rng.randrange(len(SHAPES))]
        name = f"b{i:05d} {shape}"
        p = {
            "region": f"r{rng.randrange(self.regions)}",
            "regions": sorted({f"r{rng.randrange(self.regions)}" for _ in range(3)}),
            "segment": f"s{rng.randrange(self.segments)}",
            "purpose": f"p{rng.randrange(self.purposes)}",
            "domain": f"d{rng.randrange(self.domains)}",
            "lo": 18 + rng.randrange(50),
            "span": 5 + rng.randrange(30),
            "income": float(rng.randrange(0, 100_000, 500)),
            "score": rng.randrange(300, 850),
            "amount": float(rng.randrange(0, 50_000, 250)),
            "k": 1 + rng.randrange(2),
            "total": float(rng.randrange(0, 80_000, 500)),
            "salience": rng.randrange(-10, 11),
            "group": f"g{rng.randrange(4)}",
        }
        attribute = ATTRIBUTES[rng.randrange(len(ATTRIBUTES))] if rng.random() < self.attribute_share else None
        p["call"] = rng.randrange(len(CALLS))  # drawn last: the draws before it are those of older bases
        rule = Rule(i, name, shape, p, attribute)
        rule.drl = self._drl(rule)
        return rule

    def rules(self) -> list[Rule]:
        return [self.rule(i) for i in range(self.n)]

    @staticmethod
    def _when(r: Rule) -> str:
        p = r.p
        joined = '    $a : Applicant( {first}, $id : id )\n'
        if r.shape == "multi":
            return (f'    $a : Applicant( region == "{p["region"]}", age >= {p["lo"]}, age < {p["lo"] + p["span"]}, '
                    f'income > {p["income"]}, score >= {p["score"]} )')
        if r.shape == "join":
            return (joined.format(first=f'segment == "{p["segment"]}"')
                    + f'    $l : Loan( applicant == $id, purpose == "{p["purpose"]}", amount > {p["amount"]} )')
        if r.shape in ("count", "sum", "min", "max"):
            test = {"count": f"intValue >= {p['k']}", "sum": f"doubleValue > {p['total']}",
                    "min": f"doubleValue < {p['amount']}", "max": f"doubleValue > {p['amount']}"}[r.shape]
            function = "count( 1 )" if r.shape == "count" else f"{r.shape}( $m )"
            return (joined.format(first=f'region == "{p["region"]}"')
                    + f"    Number( {test} ) from accumulate( Loan( applicant == $id, $m : amount ), {function} )")
        if r.shape == "not":
            return (joined.format(first=f'segment == "{p["segment"]}"')
                    + f'    not Loan( applicant == $id, purpose == "{p["purpose"]}" )')
        if r.shape == "exists":
            return (joined.format(first=f'region == "{p["region"]}"')
                    + f"    exists Loan( applicant == $id, amount > {p['amount']} )")
        if r.shape == "in":
            regions = ", ".join(f'"{x}"' for x in p["regions"])
            return f"    $a : Applicant( region in ( {regions} ), score > {p['score']} )"
        if r.shape == "matches":
            return f'    $a : Applicant( email matches ".*@{p["domain"]}[.]com", age > {p["lo"]} )'
        return f'    $a : Applicant( segment == "{p["segment"]}", income > {p["income"]} )'  # calls

    @staticmethod
    def _then(r: Rule) -> str:
        if r.shape == "calls":
            return f'    actions.say("bot", "{r.name}|" + {CALLS[r.p.get("call", 0)]});'
        return f'    actions.say("bot", "{r.name}");'

    @staticmethod
    def _attribute(r: Rule) -> str:
        a, p = r.attribute, r.p
        return {
            None: "",
            "salience": f"salience {p['salience']}\n",
            "agenda-group": f'agenda-group "{p["group"]}"\nauto-focus true\n',
            "no-loop": "no-loop true\n",
            "lock-on-active": "lock-on-active true\n",
            "date-effective": 'date-effective "01-Jan-2020"\n',
            "date-future": 'date-effective "01-Jan-2099"\n',
            "date-expires": 'date-expires "01-Jan-2099"\n',
        }[a]

    def _drl(self, r: Rule) -> str:
        return f'rule "{r.name}"\n{self._attribute(r)}when\n{self._when(r)}\nthen\n{self._then(r)}\nend\n'

    def drl_files(self) -> dict[str, str]:
        """``types.drl`` and ``rules_NNN.drl`` files of 500 rules each."""
        files = {"types.drl": TYPES_DRL}
        for start in range(0, self.n, RULES_PER_FILE):
            body = "\n".join(self.rule(i).drl for i in range(start, min(self.n, start + RULES_PER_FILE)))
            files[f"rules_{start // RULES_PER_FILE:03d}.drl"] = f"package {PACKAGE};\n\n{body}"
        return files

    # ------------------------------------------------------------------ facts

    def facts(self, k: int, applicants: int = 2, loans: int = 3) -> list[dict[str, Any]]:
        """A request: ``applicants`` applicants and ``loans`` loans (each of one of them), drawn
        from the same domains as the rules' constants; ``k`` varies them."""
        rng = random.Random(f"facts:{self.seed}:{k}")
        out: list[dict[str, Any]] = []
        for a in range(applicants):
            out.append({"type": "Applicant", "id": f"a{a}", "age": 18 + rng.randrange(60),
                        "income": float(rng.randrange(0, 120_000, 250)), "score": rng.randrange(300, 850),
                        "region": f"r{rng.randrange(self.regions)}", "segment": f"s{rng.randrange(self.segments)}",
                        "email": f"a{a}@d{rng.randrange(self.domains)}.com"})
        for n in range(loans):
            out.append({"type": "Loan", "id": f"l{n}", "applicant": f"a{rng.randrange(applicants)}",
                        "amount": float(rng.randrange(0, 60_000, 250)), "term": 12 * (1 + rng.randrange(5)),
                        "purpose": f"p{rng.randrange(self.purposes)}"})
        return out

    # ------------------------------------------------------------------ the model

    def expected(self, facts: list[dict[str, Any]]) -> dict[str, list[str]]:
        """Rule name -> the texts its firings say (one per firing), by the rules' meaning in Drools:
        a rule fires once per match; an accumulate over no loans gives count 0 and sum 0, and no
        min or max (no match); ``exists`` fires once per applicant; a rule effective from 2099 never
        fires. Attributes change no counts here: no then-part modifies a fact."""
        applicants = [f for f in facts if f["type"] == "Applicant"]
        loans = [f for f in facts if f["type"] == "Loan"]
        out: dict[str, list[str]] = {}
        for r in self.rules():
            if r.attribute == "date-future":
                continue
            texts = [self._text(r, a) for a, count in self._matches(r, applicants, loans) for _ in range(count)]
            if texts:
                out[r.name] = texts
        return out

    @staticmethod
    def _text(r: Rule, a: dict[str, Any]) -> str:
        if r.shape != "calls":
            return r.name
        return f"{r.name}|" + {
            0: lambda: f"{a['id']}|{max(a['age'], 1)}",
            1: lambda: f"{a['id']}|{float(max(a['income'], 0))}",
            2: lambda: f"{a['id']}/{a['score']}/{a['age']}",
        }[r.p.get("call", 0)]()

    @staticmethod
    def _matches(r: Rule, applicants: list[dict[str, Any]], loans: list[dict[str, Any]]):
        """(applicant, number of firings for it) for each applicant the rule matches."""
        p = r.p
        for a in applicants:
            mine = [x for x in loans if x["applicant"] == a["id"]]
            amounts = [x["amount"] for x in mine]
            if r.shape == "multi":
                ok = (a["region"] == p["region"] and p["lo"] <= a["age"] < p["lo"] + p["span"]
                      and a["income"] > p["income"] and a["score"] >= p["score"])
                count = int(ok)
            elif r.shape == "join":
                count = sum(1 for x in mine if x["purpose"] == p["purpose"] and x["amount"] > p["amount"]) \
                    if a["segment"] == p["segment"] else 0
            elif r.shape in ("count", "sum", "min", "max"):
                if a["region"] != p["region"]:
                    count = 0
                elif r.shape == "count":
                    count = int(len(mine) >= p["k"])
                elif r.shape == "sum":
                    count = int(sum(amounts) > p["total"])
                elif r.shape == "min":
                    count = int(bool(amounts) and min(amounts) < p["amount"])
                else:
                    count = int(bool(amounts) and max(amounts) > p["amount"])
            elif r.shape == "not":
                count = int(a["segment"] == p["segment"] and not any(x["purpose"] == p["purpose"] for x in mine))
            elif r.shape == "exists":
                count = int(a["region"] == p["region"] and any(x["amount"] > p["amount"] for x in mine))
            elif r.shape == "in":
                count = int(a["region"] in p["regions"] and a["score"] > p["score"])
            elif r.shape == "matches":
                count = int(bool(re.fullmatch(rf".*@{p['domain']}[.]com", a["email"])) and a["age"] > p["lo"])
            else:
                count = int(a["segment"] == p["segment"] and a["income"] > p["income"])
            if count:
                yield a, count
