"""The knowledge editor's operations over the live knowledge base: the class tree, the individuals
with their typed values (asserted and inferred), one value changed, one SWRL rule read, checked or
replaced, and "what does this infer for …".

Why on top of :class:`~gateway.ontology.knowledge.KnowledgeBase` and not in it: the knowledge base
holds whole texts and their versions (the one thing every reader shares); the editor turns a small
edit — one value, one rule — into a new whole text and hands it to ``replace``, so every edit is
checked by Pellet, versioned, live at once and rolled back exactly like a whole-text edit.
"""

from __future__ import annotations

import re
from typing import Any

from gateway.ontology.knowledge import KnowledgeBase, KnowledgeInvalid, digest
from gateway.ontology.model import OntologyModel, local, read_model
from gateway.ontology.reasoner import ReasonerError
from gateway.ontology.swrl import (
    Atom,
    RuleInvalid,
    append_rule,
    describe,
    parse_rule,
    read_rules,
    replace_rule,
    rule_lines,
)
from gateway.ontology.values import (
    XSD,
    ValueInvalid,
    _prefixes,
    _turtle_literal,
    expectation,
    lexical_form,
    set_value_in_text,
    value_type,
)
from gateway.base.versions import VersionInfo


class NotFound(LookupError):
    """No such individual, property or rule."""


class KnowledgeEditor:
    def __init__(self, knowledge: KnowledgeBase) -> None:
        self.knowledge = knowledge
        self.last_changes: list[dict[str, Any]] = []  # what the last checked rule would change

    # ---- reading -------------------------------------------------------------------------------
    def model(self) -> OntologyModel:
        k = self.knowledge
        return read_model(k.text("ontology"), k.base, k.files["ontology"].endswith((".ttl", ".n3")))

    def classes(self) -> dict[str, Any]:
        model = self.model()
        return {"version": self._version("ontology"), "classes": model.class_tree()}

    def properties(self) -> list[dict[str, Any]]:
        return [{"name": p.name, "kind": p.kind, "range": p.range, "domain": p.domain, "comment": p.comment,
                 **({"unit": p.unit, "limits": p.limits, "expects": expectation(p.range, p.unit, p.limits)}
                    if p.kind == "data" else {})}
                for p in sorted(self.model().properties.values(), key=lambda p: p.name)]

    def individuals(self) -> dict[str, Any]:
        model = self.model()
        return {"version": self._version("ontology"), "hash": digest(self.knowledge.text("ontology")),
                "individuals": [self._individual(model, name) for name in sorted(model.individuals)],
                "properties": self.properties()}

    def individual(self, name: str) -> dict[str, Any]:
        model = self.model()
        if name not in model.individuals:
            raise NotFound(f"the ontology has no individual {name!r}")
        return self._individual(model, name)

    def _individual(self, model: OntologyModel, name: str) -> dict[str, Any]:
        ind = model.individuals[name]
        rules = self._rules(model)
        values = [{"property": v.property, "lexical": v.lexical, "value": self.knowledge.value(f"{name}.{v.property}"),
                   "datatype": value_type(model, name, v.property), "inferred": False,
                   **self._value_words(model, name, v.property, v.lexical)}
                  for v in ind.values]
        inferred = self._inferred_values(model, name, rules)
        return {"name": name, "types": ind.types, "values": values + inferred,
                "links": [{"property": p, "individual": o} for p, o in ind.links],
                "comment": ""}

    @staticmethod
    def _value_words(model: OntologyModel, individual: str, prop: str, example: str = "") -> dict[str, Any]:
        """The unit, limits and expected value in words of ``individual.prop`` (for the editor)."""
        info = model.properties.get(prop)
        unit, limits = (info.unit, dict(info.limits)) if info else ("", {})
        return {"unit": unit, "limits": limits,
                "expects": expectation(value_type(model, individual, prop), unit, limits, example)}

    def _inferred_values(self, model: OntologyModel, name: str, rules: list[Any]) -> list[dict[str, Any]]:
        out = []
        for fact in self.knowledge.inferred:
            if local(str(fact["subject"]), model.base) != name or fact.get("object_type") != "literal":
                continue
            prop = local(str(fact["predicate"]), model.base) or str(fact["predicate"])
            out.append({"property": prop, "lexical": str(fact.get("lexical", fact["object"])), "value": fact["object"],
                        "datatype": str(fact.get("datatype", "")).rsplit("#", 1)[-1] or "string", "inferred": True,
                        "rules": [r.number for r in rules if prop in {a.name for a in r.head}]})
        return sorted(out, key=lambda v: v["property"])

    def _rules(self, model: OntologyModel) -> list[Any]:
        return read_rules(self.knowledge.text("swrl"), model)

    def _version(self, kind: str) -> int | None:
        info = self.knowledge.info(kind)
        return info.version if info else None

    # ---- one value -----------------------------------------------------------------------------
    def set_value(self, individual: str, prop: str, value: Any, *, author: str, comment: str = "",
                  base_hash: str | None = None) -> tuple[VersionInfo, dict[str, Any]]:
        """Check ``value`` against the property's xsd type, write it into the ontology text and
        replace the ontology (Pellet-checked, versioned, live); ValueInvalid names the field."""
        model = self.model()
        if individual not in model.individuals:
            raise NotFound(f"the ontology has no individual {individual!r}")
        info = model.properties.get(prop)
        if info is None:
            raise ValueInvalid("property", f"{prop!r} is not a property of the ontology")
        if info.kind != "data":
            raise ValueInvalid("property", f"{prop} is an object property (it links individuals), not a data value")
        if value is None or (isinstance(value, str) and not value.strip()):
            raise ValueInvalid("value", f"{prop}: a value is needed")
        datatype = value_type(model, individual, prop)
        now = next((v.lexical for v in model.individuals[individual].values if v.property == prop), "")
        lexical = lexical_form(prop, datatype, value, info.unit, info.limits, now)
        current = self.knowledge.text("ontology")
        text = set_value_in_text(current, model, individual, prop, lexical, datatype)
        # the edit was made on `current`: a change saved meanwhile is a conflict, never overwritten
        saved = self.knowledge.replace("ontology", text, author=author, base_hash=base_hash or digest(current),
                                       comment=comment or f"{individual}.{prop} = {lexical}")
        return saved, {"individual": individual, "property": prop, "lexical": lexical, "datatype": datatype,
                       "value": self.knowledge.value(f"{individual}.{prop}")}

    # ---- a new individual ----------------------------------------------------------------------
    def add_individual(self, name: str, cls: str, values: dict[str, Any] | None = None, *, author: str,
                       comment: str = "") -> tuple[VersionInfo, dict[str, Any]]:
        """Add individual ``name`` of class ``cls`` with data ``values`` (``label`` is its
        ``rdfs:label``; other keys are data properties, type-checked), appended to the ontology text
        as one Turtle statement and saved like any edit (Pellet-checked, versioned, live at once: a
        new Beverage can be ordered by talking to Pepper straight away). ValueInvalid names the field."""
        model = self.model()
        if not re.fullmatch(r"[A-Za-z_][\w-]*", name or ""):
            raise ValueInvalid("name", f"{name!r}: a name is a letter or '_' then letters, digits, '_' or '-'")
        if name in model.individuals or name in model.classes or name in model.properties:
            raise ValueInvalid("name", f"{name!r} is already in the ontology")
        if cls not in model.classes:
            raise ValueInvalid("class", f"{cls!r} is not a class of the ontology (classes: {', '.join(sorted(model.classes))})")
        current = self.knowledge.text("ontology")
        if not self.knowledge.files["ontology"].endswith((".ttl", ".n3")):
            raise ValueInvalid("name", "individuals can be added to a Turtle ontology only")
        prefix = next(iter(_prefixes(current, model.base)), None)
        xsd = next(iter(_prefixes(current, XSD)), None)

        def term(local_name: str) -> str:
            return f"{prefix}:{local_name}" if prefix is not None else f"<{model.base}{local_name}>"

        parts = [f"{term(name)} a <http://www.w3.org/2002/07/owl#NamedIndividual>, {term(cls)}"]
        shown: dict[str, str] = {}
        for prop, value in (values or {}).items():
            if prop == "label":
                if not isinstance(value, str) or not value.strip():
                    raise ValueInvalid("values.label", "label: a non-empty text is needed")
                parts.append(f"<http://www.w3.org/2000/01/rdf-schema#label> {_turtle_literal(value.strip(), 'string', xsd)}")
                shown[prop] = value.strip()
                continue
            info = model.properties.get(prop)
            if info is None or info.kind != "data":
                raise ValueInvalid(f"values.{prop}", f"{prop!r} is not a data property of the ontology")
            if value is None or (isinstance(value, str) and not value.strip()):
                raise ValueInvalid(f"values.{prop}", f"{prop}: a value is needed")
            datatype = info.range or "string"
            try:
                lexical = lexical_form(prop, datatype, value)
            except ValueInvalid as exc:
                raise ValueInvalid(f"values.{prop}", exc.message) from None
            parts.append(f"{term(prop)} {_turtle_literal(lexical, datatype, xsd)}")
            shown[prop] = lexical
        note = f"# {comment.strip()}\n" if comment.strip() and "\n" not in comment.strip() else ""
        text = current.rstrip("\n") + "\n" + note + " ;\n    ".join(parts) + " .\n"
        saved = self.knowledge.replace("ontology", text, author=author, base_hash=digest(current),
                                       comment=comment or f"new {cls} {name}")
        return saved, {"name": name, "class": cls, "values": shown}

    # ---- SWRL rules ----------------------------------------------------------------------------
    def rules(self) -> dict[str, Any]:
        model = self.model()
        text = self.knowledge.text("swrl")
        return {"version": self._version("swrl"), "hash": digest(text),
                "rules": [describe(r, model) for r in read_rules(text, model)]}

    def rule(self, number: int) -> dict[str, Any]:
        rules = self.rules()
        if not 1 <= number <= len(rules["rules"]):
            raise NotFound(f"there is no rule {number} (rules 1-{len(rules['rules'])})")
        return {"version": rules["version"], "hash": rules["hash"], **rules["rules"][number - 1]}

    def check_rule(self, number: int | None, text: str, comment: str = "") -> tuple[list[dict[str, Any]], str]:
        """Errors of a candidate rule (number None: a new rule), and the whole rules text it makes."""
        current = self.knowledge.text("swrl")
        count = len(rule_lines(current))
        if number is not None and not 1 <= number <= count:
            raise NotFound(f"there is no rule {number} (rules 1-{count})")
        rule_no = number if number is not None else count + 1
        candidate = replace_rule(current, number, text) if number is not None else append_rule(current, text, comment)
        lines = rule_lines(candidate)
        line = lines[rule_no - 1][0] if rule_no <= len(lines) else len(candidate.splitlines()) + 1
        where = {"rule": rule_no, "line": line, "field": "text"}
        if not text.strip() or "\n" in text.strip():
            return [{**where, "column": 0, "atom": "", "message": "a rule is one line: body atoms -> head atoms"}], candidate
        try:
            body, head = parse_rule(text.strip(), self.model())
        except RuleInvalid as exc:
            return [{**where, "column": exc.column, "atom": exc.atom, "message": f"rule {rule_no}: {exc.message}"}], candidate
        errors, reasoned = self.knowledge.trial("swrl", candidate)
        self.last_changes = self._changes(reasoned) if reasoned else []
        out = []
        for e in errors:
            ours = e.get("line") == line or not e.get("line")
            atom = pellet_atom(e["message"], body, head) if ours else None
            out.append({**where, "column": atom.column if atom else e.get("column", 0), "atom": atom.text if atom else "",
                        "message": f"rule {rule_no}: {e['message']}" if ours else e["message"]})
        return out, candidate

    def _changes(self, reasoned: dict[str, Any]) -> list[dict[str, Any]]:
        """Inferred values of the ontology's individuals that a candidate would change (before → after)."""
        base = self.knowledge.base

        def values(facts: list[dict[str, Any]]) -> dict[str, str]:
            return {f"{local(str(f['subject']), base)}.{local(str(f['predicate']), base)}": str(f.get("lexical", f["object"]))
                    for f in facts if f.get("object_type") == "literal" and local(str(f["subject"]), base)}

        now, then = values(self.knowledge.inferred), values(reasoned["inferred"])
        return [{"value": k, "before": now.get(k), "after": then.get(k)}
                for k in sorted(set(now) | set(then)) if now.get(k) != then.get(k)]

    def save_rule(self, number: int | None, text: str, *, author: str, comment: str = "",
                  base_hash: str | None = None) -> tuple[VersionInfo, int]:
        current = self.knowledge.text("swrl")
        errors, candidate = self.check_rule(number, text, comment if number is None else "")
        if errors:
            raise KnowledgeInvalid("swrl", errors)
        saved = self.knowledge.replace("swrl", candidate, author=author, base_hash=base_hash or digest(current),
                                       comment=comment or (f"rule {number}" if number else "new rule"))
        return saved, number or len(rule_lines(candidate))

    # ---- what does it infer ----------------------------------------------------------------------
    def explain(self, name: str) -> dict[str, Any]:
        """What Pellet infers for an individual of the ontology: types and values, and why."""
        model = self.model()
        if name not in model.individuals:
            raise NotFound(f"the ontology has no individual {name!r}")
        rules = self._rules(model)
        asserted = model.individuals[name].types
        types = [t["class"] for t in self.knowledge.inferred_types if local(t["individual"], model.base) == name]
        return {"individual": name, "asserted_types": asserted,
                "types": [self._why_type(model, rules, asserted, local(t, model.base) or t) for t in types],
                "values": self._inferred_values(model, name, rules),
                "links": self._inferred_links(model, name, rules)}

    def try_individual(self, individual: dict[str, Any]) -> dict[str, Any]:
        """What Pellet would infer for a new individual (not stored): ``{id, types, properties}``."""
        if not isinstance(individual, dict) or not isinstance(individual.get("id"), str):
            raise ReasonerError("expected {id, types, properties}", "individual")
        model = self.model()
        rules = self._rules(model)
        result = self.knowledge.reason({"individuals": [individual]})
        name = individual["id"]
        asserted = [t for t in individual.get("types", []) if isinstance(t, str)]
        types = [t["class"] for t in result["types"] if local(t["individual"], model.base) == name]
        values = []
        for fact in result["inferred"]:
            if local(str(fact["subject"]), model.base) == name and fact.get("object_type") == "literal":
                prop = local(str(fact["predicate"]), model.base) or str(fact["predicate"])
                values.append({"property": prop, "lexical": str(fact.get("lexical", fact["object"])),
                               "value": fact["object"], "inferred": True,
                               "datatype": str(fact.get("datatype", "")).rsplit("#", 1)[-1],
                               "rules": [r.number for r in rules if prop in {a.name for a in r.head}]})
        return {"individual": name, "asserted_types": asserted,
                "types": [self._why_type(model, rules, asserted, local(t, model.base) or t) for t in types],
                "values": sorted(values, key=lambda v: v["property"]), "links": []}

    def _why_type(self, model: OntologyModel, rules: list[Any], asserted: list[str], cls: str) -> dict[str, Any]:
        by_rules = [r.number for r in rules if cls in {a.name for a in r.head}]
        parents = [a for a in asserted if cls in model.superclasses(a)]
        because = (f"rule {', '.join(map(str, by_rules))}" if by_rules else "") or \
            (f"{parents[0]} is a kind of {cls}" if parents else "the ontology's axioms")
        return {"class": cls, "rules": by_rules, "because": because}

    def _inferred_links(self, model: OntologyModel, name: str, rules: list[Any]) -> list[dict[str, Any]]:
        out = []
        for fact in self.knowledge.inferred:
            if local(str(fact["subject"]), model.base) == name and fact.get("object_type") == "iri":
                prop = local(str(fact["predicate"]), model.base) or str(fact["predicate"])
                out.append({"property": prop, "individual": local(str(fact["object"]), model.base) or fact["object"],
                            "rules": [r.number for r in rules if prop in {a.name for a in r.head}]})
        return out


def pellet_atom(message: str, body: list[Atom], head: list[Atom]) -> Atom | None:
    """Where in a rule a Pellet error points (Pellet names no position): for an inconsistency, the
    rule's conclusion (the live rules and ontology were consistent without this rule, and its
    conclusion is all it adds); else the first atom the message names; None when neither."""
    if "inconsistent" in message:
        return head[0] if head else None
    return next((atom for atom in [*body, *head] if re.search(rf"\b{re.escape(atom.name)}\b", message)), None)
