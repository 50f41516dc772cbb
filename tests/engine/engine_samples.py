"""Rule texts and the engine factory shared by the engine tests."""

from pathlib import Path

from gateway.config import Settings
from gateway.engine import Engine


def engine_with(root: Path, name: str, files: dict[str, str], **engine_settings) -> Engine:
    """An engine keeping its data under ``root`` with ``files`` deployed as rule set ``name``."""
    engine = Engine(Settings(data_dir=str(root / "data"), engine={"rules_dir": str(root / "rules"), **engine_settings}))
    engine.deploy(name, files)
    return engine

TYPES = """package org.printeps.test;
import org.printeps.gateway.Actions;
global Actions actions;

declare Customer
    id: String
    age: int
    gender: String
    distance: double
end

declare Group
    id: String
    size: int
end
"""

RULES = """package org.printeps.test;

rule "greet adult"
when
    $c: Customer(age >= 18)
then
    actions.say("pepper", "Hello " + $c.getId());
end

rule "group of two"
when
    Group(size == 2)
then
    actions.say("pepper", "Welcome. Two seats?");
    actions.move("pepper", "table1");
    actions.gesture("pepper", "bow");
end
"""
