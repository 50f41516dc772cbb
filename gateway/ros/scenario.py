"""Sensor scenario files: who walks where in front of the entrance sensor, and when.

A scenario is YAML (see scenarios/teahouse-reception.yaml). Each ``event`` moves a set of people
along a straight line in distance from the sensor: ``from`` → ``to`` metres over ``duration`` s,
starting ``at`` s, then they stay visible for ``stay`` s. Kinds only name the intent:
``arrive`` (walk up to the entrance), ``pass`` (walk by at a constant distance), ``leave``.
Plain Python: ``readings()`` yields the Entrance readings the simulator publishes, so tests and the
benchmark use the exact same data. Bad files fail with file:line:column and the field.
"""

from __future__ import annotations

import random
from pathlib import Path
from typing import Any, Iterator, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator


class ScenarioError(ValueError):
    """A scenario file that cannot be used: ``file:line:column: field: message``."""


class Person(BaseModel):
    model_config = ConfigDict(extra="forbid")
    id: str = Field(min_length=1)
    age: int = Field(default=-1, ge=-1, le=130)
    gender: Literal["male", "female", "unknown", ""] = "unknown"


class Event(BaseModel):
    model_config = ConfigDict(extra="forbid", populate_by_name=True)
    at: float = Field(ge=0)
    kind: Literal["arrive", "pass", "leave"] = "arrive"
    label: str = ""
    people: list[Person] = Field(min_length=1, max_length=100)
    from_: float = Field(alias="from", ge=0, le=20)
    to: float = Field(ge=0, le=20)
    duration: float = Field(gt=0, le=600)
    stay: float = Field(default=0.0, ge=0, le=600)
    spacing: float = Field(default=0.05, ge=0, le=2, description="extra metres between members")

    def distance(self, t: float) -> float | None:
        """Distance of the event's first member at scenario time ``t`` (None: not visible)."""
        if t < self.at or t > self.at + self.duration + self.stay:
            return None
        k = min(1.0, (t - self.at) / self.duration)
        return self.from_ + (self.to - self.from_) * k


class Scenario(BaseModel):
    model_config = ConfigDict(extra="forbid")
    name: str
    description: str = ""
    sensor_id: str = "kinect1"
    location: str = "entrance"
    distance_to_entrance: float = Field(default=3.3, gt=0, le=20)
    rate_hz: float = Field(default=2.0, gt=0, le=100)
    noise_m: float = Field(default=0.0, ge=0, le=0.5)
    seed: int = 1
    events: list[Event] = Field(min_length=1)

    @model_validator(mode="after")
    def _unique_people(self) -> "Scenario":
        seen: dict[str, int] = {}
        for i, e in enumerate(self.events):
            for p in e.people:
                if p.id in seen:
                    raise ValueError(f"person id {p.id!r} is used by events {seen[p.id]} and {i}")
                seen[p.id] = i
        return self

    @property
    def duration(self) -> float:
        return max(e.at + e.duration + e.stay for e in self.events)

    def readings(self, start: float = 0.0, rate_hz: float | None = None) -> Iterator[dict[str, Any]]:
        """Entrance readings at ``rate_hz`` from scenario time 0 to the end; stamps = start + t."""
        rate = rate_hz or self.rate_hz
        rng = random.Random(self.seed)
        n = int(self.duration * rate) + 2
        for i in range(n):
            t = i / rate
            customers = []
            for e in self.events:
                d = e.distance(t)
                if d is None:
                    continue
                for j, p in enumerate(e.people):
                    dist = max(0.0, d + j * e.spacing + (rng.gauss(0, self.noise_m) if self.noise_m else 0.0))
                    customers.append({"id": p.id, "distance": round(dist, 4), "age": p.age,
                                      "age_range_min": max(-1, p.age - 5) if p.age >= 0 else -1,
                                      "age_range_max": p.age + 5 if p.age >= 0 else -1,
                                      "gender": p.gender if p.gender != "unknown" else ""})
            yield {"id": f"{self.sensor_id}-{i}", "number_of_customers": len(customers), "customers": customers,
                   "stamp": start + t, "t": t, "location": self.location}


class Party(BaseModel):
    """People seated at a table from ``from`` s to ``to`` s of scenario time."""

    model_config = ConfigDict(extra="forbid", populate_by_name=True)
    label: str = ""
    table: str = Field(min_length=1)
    people: list[str] = Field(min_length=1, max_length=20)
    from_: float = Field(alias="from", ge=0)
    to: float = Field(gt=0)

    @model_validator(mode="after")
    def _in_order(self) -> "Party":
        if self.to <= self.from_:
            raise ValueError(f"'to' ({self.to}) must be after 'from' ({self.from_})")
        return self


class TableScenario(BaseModel):
    """What the table sensors see: every table (each sensor reports its own table) and the parties
    seated at them (see scenarios/teahouse-tables.yaml)."""

    model_config = ConfigDict(extra="forbid")
    name: str
    description: str = ""
    rate_hz: float = Field(default=2.0, gt=0, le=100)
    duration: float = Field(gt=0, le=3600)
    tables: list[str] = Field(min_length=1)
    parties: list[Party] = Field(default_factory=list)

    @model_validator(mode="after")
    def _known_tables(self) -> "TableScenario":
        for i, party in enumerate(self.parties):
            if party.table not in self.tables:
                raise ValueError(f"parties.{i}.table: {party.table!r} is not one of the tables {self.tables}")
        return self

    def readings(self, start: float = 0.0, rate_hz: float | None = None) -> Iterator[dict[str, Any]]:
        """TeahouseObject readings at ``rate_hz``: each table, then everyone seated; stamps = start + t."""
        rate = rate_hz or self.rate_hz
        for i in range(int(self.duration * rate) + 1):
            t = i / rate
            for table in self.tables:
                yield {"id": table, "type": "Table", "location": table, "x": 0.0, "y": 0.0, "distance": 0.0,
                       "stamp": start + t, "t": t}
                for party in self.parties:
                    if party.table == table and party.from_ <= t < party.to:
                        for j, person in enumerate(party.people):
                            yield {"id": person, "type": "Customer", "location": table, "x": 0.5 * j, "y": 0.5,
                                   "distance": 0.6, "stamp": start + t, "t": t}


def _node_at(root: yaml.Node, loc: tuple[Any, ...]) -> yaml.Node:
    node = root
    for key in loc:
        if isinstance(node, yaml.MappingNode):
            match = [v for k, v in node.value if k.value == str(key) or (key == "from_" and k.value == "from")]
            if not match:
                break
            node = match[0]
        elif isinstance(node, yaml.SequenceNode) and isinstance(key, int) and key < len(node.value):
            node = node.value[key]
        else:
            break
    return node


def load_scenario(path: str | Path, model: type[BaseModel] = Scenario) -> Any:
    """Read and validate a scenario file (an entrance ``Scenario`` or a ``TableScenario``); errors
    name file, line, column and field."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ScenarioError(f"{path}: cannot read: {exc.strerror}") from None
    try:
        root = yaml.compose(text)
        data = yaml.safe_load(text)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark
        where = f"{path}:{mark.line + 1}:{mark.column + 1}" if mark else str(path)
        raise ScenarioError(f"{where}: YAML syntax error: {exc.problem}") from None
    if not isinstance(data, dict) or root is None:
        raise ScenarioError(f"{path}:1:1: a scenario must be a mapping with 'name' and "
                            f"{'events' if model is Scenario else 'tables'}")
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        lines = []
        for err in exc.errors():
            loc = tuple(err["loc"])
            node = _node_at(root, loc)
            field = ".".join("from" if p == "from_" else str(p) for p in loc) or "(top level)"
            lines.append(f"{path}:{node.start_mark.line + 1}:{node.start_mark.column + 1}: {field}: {err['msg']}")
        raise ScenarioError("\n".join(lines)) from None
