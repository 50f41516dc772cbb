"""Small rule sets the API tests deploy (kept here so the tests do not depend on rules/drl)."""

TYPES = """package org.printeps.apitest;

import org.printeps.gateway.Actions;

global Actions actions;

declare Customer
    id : String
    age : int
    category : String
end
"""

RULES = """package org.printeps.apitest;

import org.printeps.gateway.Actions;

global Actions actions;

rule "Adult"
when
    $c : Customer( category == null, age >= 18 )
then
    modify($c) { setCategory("adult") };
end

rule "Greet adult"
when
    $c : Customer( category == "adult" )
then
    actions.say("pepper", "Welcome " + $c.getId() + " (MARKER)");
end
"""


def files(marker: str = "v1") -> dict[str, str]:
    """A two-file rule set whose greeting names ``marker`` (to tell versions apart by behaviour)."""
    return {"types.drl": TYPES, "greet.drl": RULES.replace("MARKER", marker)}


BROKEN = {
    "types.drl": TYPES,
    "greet.drl": "package org.printeps.apitest;\n\nrule \"Broken\"\nwhen\n    Customer( age >\nthen\nend\n",
}

FACTS = [
    {"type": "Customer", "id": "c1", "age": 34},
    {"type": "Customer", "id": "c2", "age": 7},
]
