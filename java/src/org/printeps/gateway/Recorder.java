package org.printeps.gateway;

import java.util.LinkedHashMap;
import java.util.List;
import java.util.Map;

import org.kie.api.event.rule.AfterMatchFiredEvent;
import org.kie.api.event.rule.BeforeMatchFiredEvent;
import org.kie.api.event.rule.DefaultAgendaEventListener;

/**
 * Records, while rules fire, which rule fired with which facts, and tells {@link Actions} which
 * rule is requesting its actions. Matched facts are written to JSON at the moment of firing, so the
 * answer shows what the rule saw, not what later rules changed.
 */
final class Recorder extends DefaultAgendaEventListener {
    private final Actions actions;
    private final TypeRegistry types;
    private StringBuilder fired = new StringBuilder();
    private int firedCount;
    private final Map<String, Integer> counts = new LinkedHashMap<String, Integer>();
    private final boolean recordFacts;

    /**
     * When no fact can change while the rules fire (a request-join fire: plain rules only call
     * globals), each matched fact's number in {@link #table}, where its JSON is written once; a
     * firing lists the numbers and the answer carries the table ({@code "factTable"}; the gateway's
     * {@code results.fired_of} puts a copy of the facts back in each firing). Null otherwise. Why: a fact is
     * written, sent and parsed at every firing that matched it (~74 firings of 5 facts per request
     * at 10,000 business rules; parsing them was ~0.1 ms of a ~1.3 ms fire).
     */
    private final java.util.IdentityHashMap<Object, Integer> written;
    private final StringBuilder table = new StringBuilder();

    Recorder(Actions actions, TypeRegistry types, boolean recordFacts) {
        this(actions, types, recordFacts, false);
    }

    /** A recorder that writes each fact once when {@code factsFixed} (see {@link #written}). */
    Recorder(Actions actions, TypeRegistry types, boolean recordFacts, boolean factsFixed) {
        this.actions = actions;
        this.types = types;
        actions.setTypes(types);
        this.recordFacts = recordFacts;
        this.written = recordFacts && factsFixed ? new java.util.IdentityHashMap<Object, Integer>() : null;
    }

    @Override
    public void beforeMatchFired(BeforeMatchFiredEvent event) {
        actions.setCurrentRule(event.getMatch().getRule().getName());
    }

    @Override
    public void afterMatchFired(AfterMatchFiredEvent event) {
        String rule = event.getMatch().getRule().getName();
        actions.setCurrentRule(null);
        Integer c = counts.get(rule);
        counts.put(rule, c == null ? 1 : c + 1);
        if (firedCount > 0) fired.append(',');
        firedCount++;
        fired.append("{\"rule\":");
        Json.quote(fired, rule);
        if (recordFacts) {
            fired.append(",\"facts\":[");
            List<Object> objs = event.getMatch().getObjects();
            boolean first = true;
            for (int k = 0; k < objs.size(); k++) {
                Object o = objs.get(k);
                if (o instanceof RequestFacts.Marker) continue;  // a not/exists read from the request: no fact
                if (o instanceof RequestDispatch.Routed) continue;  // what a dispatched pattern read its fact from
                if (!first) fired.append(',');
                first = false;
                if (written == null) {
                    Json.write(fired, o, types);
                } else {
                    Integer number = written.get(o);
                    if (number == null) {
                        number = written.size();
                        written.put(o, number);
                        if (number > 0) table.append(',');
                        Json.write(table, o, types);
                    }
                    fired.append(number.intValue());
                }
            }
            fired.append(']');
        }
        fired.append('}');
    }

    /** Appends {"ok":true,"fireCount":n,"actions":[...],"fired":[...]} minus the closing brace. */
    void writeSuccess(StringBuilder b, int fireCount) {
        b.append("{\"ok\":true,\"fireCount\":").append(fireCount).append(",\"actions\":");
        actions.drainInto(b);
        b.append(",\"fired\":[").append(fired).append(']');
        if (written != null) b.append(",\"factTable\":[").append(table).append(']');
        reset();
    }

    /** A runaway report: the fire limit was reached and rules were still activated. */
    String runaway(int limit) {
        StringBuilder b = new StringBuilder("{\"ok\":false,\"kind\":\"runaway\",\"limit\":").append(limit).append(",\"counts\":");
        Json.write(b, counts, null);
        b.append('}');
        reset();
        return b.toString();
    }

    void reset() {
        if (fired.length() > 4096) fired = new StringBuilder(); else fired.setLength(0);
        firedCount = 0;
        counts.clear();
        if (written != null) {
            written.clear();
            table.setLength(0);
        }
        actions.setCurrentRule(null);
        actions.clear();
    }
}
