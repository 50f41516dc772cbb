"""Rule texts shared by the engine tests."""

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
