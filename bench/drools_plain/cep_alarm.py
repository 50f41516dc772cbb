"""Plain Drools, outside the gateway: the Drools documentation's "Sound the alarm" rule on the
pseudo clock, built with the executable model from the same jars (the optapy wheel's), run through
Drools' own KieSession API — no gateway engine, runner, batch or JSON on the way.

Why: the gateway fires "alarm kitchen" when the clock is advanced 4 s, then 5.999 s, then 0.002 s,
but not when it is advanced 4 s then 7 s (issue 30). This shows whether Drools itself does that.

Usage (project venv, from the repository root): PYTHONPATH=$PWD .venv/bin/python bench/drools_plain/cep_alarm.py
"""

from __future__ import annotations

import sys

from gateway.base import jvm

DRL = """package org.plain.cep;
global java.util.List out;

declare FireDetected
    @role(event)
    room : String
end

declare SprinklerActivated
    @role(event){expires}
    room : String
end

rule "Sound the alarm"
when
    $f : FireDetected( )
    not( SprinklerActivated( room == $f.room, this after[0s,10s] $f ) )
then
    out.add("alarm " + $f.getRoom());
end
"""



def container(expires: str = ""):
    """The rules built with the executable model (ExecutableModelProject), as the gateway builds;
    a KieBase in stream mode (no kmodule.xml: the jars have no XML support)."""
    ks = jvm.jclass("org.kie.api.KieServices").Factory.get()
    kfs = ks.newKieFileSystem()
    kfs.write("src/main/resources/org/plain/cep/cep.drl", DRL.replace("{expires}", expires))
    project = jvm.jclass("org.drools.model.codegen.ExecutableModelProject")
    builder = ks.newKieBuilder(kfs).buildAll(project.class_)
    messages = builder.getResults().getMessages()
    if not messages.isEmpty():
        raise SystemExit(str(messages))
    kc = ks.newKieContainer(builder.getKieModule().getReleaseId())
    conf = ks.newKieBaseConfiguration()
    conf.setOption(jvm.jclass("org.kie.api.conf.EventProcessingOption").STREAM)
    return ks, kc.newKieBase(conf)


def run(built, steps_ms: list[int], trace: bool) -> list[str]:
    """Inserts a fire in the kitchen and one in the hall at 0, fires, advances 4 s, inserts a
    sprinkler in the kitchen, fires, then advances by each of ``steps_ms`` and fires after each.
    Returns what fired, each with the clock time it fired at."""
    ks, kbase = built
    sconf = ks.newKieSessionConfiguration()
    sconf.setOption(jvm.jclass("org.kie.api.runtime.conf.ClockTypeOption").PSEUDO)
    session = kbase.newKieSession(sconf, None)
    out = jvm.jclass("java.util.ArrayList")()
    session.setGlobal("out", out)
    clock = session.getSessionClock()
    time_unit = jvm.jclass("java.util.concurrent.TimeUnit").MILLISECONDS
    fired: list[str] = []

    def fire() -> None:
        before = out.size()
        session.fireAllRules()
        for k in range(before, out.size()):
            fired.append(f"{out.get(k)} at {clock.getCurrentTime()} ms")
        if trace:
            facts = sorted(f"{o.getClass().getSimpleName()}({o.getRoom()})" for o in session.getObjects())
            print(f"  t={clock.getCurrentTime()} ms facts={facts} fired so far={fired}")

    fd = session.getKieBase().getFactType("org.plain.cep", "FireDetected")
    sa = session.getKieBase().getFactType("org.plain.cep", "SprinklerActivated")

    def new(fact_type, room):
        o = fact_type.newInstance()
        fact_type.set(o, "room", room)
        return o

    session.insert(new(fd, "kitchen"))
    session.insert(new(fd, "hall"))
    fire()
    clock.advanceTime(4000, time_unit)
    session.insert(new(sa, "kitchen"))
    fire()
    for step in steps_ms:
        clock.advanceTime(step, time_unit)
        fire()
    session.dispose()
    return fired


def main() -> None:
    jvm.start()
    trace = "-v" in sys.argv
    for expires in ("", "\n    @expires(10s)"):
        built = container(expires)
        print("SprinklerActivated", "with @expires(10s)" if expires else "as in the documentation (expiry inferred)")
        for steps in ([7000], [5999, 2], [5999, 1, 1], [6000, 1], [5000, 2000], [1000] * 7):
            print(f"  advance 4000 ms, then {steps} ms: {run(built, steps, trace)}")


if __name__ == "__main__":
    main()
