package org.printeps.gateway;

import java.util.ArrayList;
import java.util.HashMap;
import java.util.List;
import java.util.Map;
import java.util.concurrent.TimeUnit;

import org.kie.api.runtime.KieSession;
import org.kie.api.runtime.rule.FactHandle;
import org.kie.api.time.SessionPseudoClock;

/**
 * A long-lived stateful session for event streams: facts stay between calls, events carry their
 * own timestamps and drive a pseudo clock, so replaying recorded data gives the same answers.
 * All methods are synchronized: a KieSession is not thread-safe.
 */
public final class Session {
    private final Runner runner;
    private final KieSession session;
    private final Actions actions = new Actions();
    private final Recorder recorder;
    private final SessionPseudoClock clock;
    private final Map<String, FactHandle> byId = new HashMap<String, FactHandle>();

    public Session(Runner runner, boolean recordFacts) {
        this.runner = runner;
        this.session = runner.newSession();
        if (Runner.declaresGlobal(session.getKieBase(), "actions")) session.setGlobal("actions", actions);
        this.recorder = new Recorder(actions, runner.types(), recordFacts);
        session.addEventListener(recorder);
        this.clock = session.getSessionClock();
    }

    /** Inserts facts (a JSON list); facts with an "id" can later be updated or retracted by it. */
    public synchronized String insert(String factsJson) {
        return insertAt(factsJson, Long.MIN_VALUE);
    }

    /**
     * Inserts facts stamped with {@code timestampMs} and fires, in one call: the stream path, where
     * every event is pushed and answered on its own (one JPype crossing instead of two).
     */
    public synchronized String pushAt(String factsJson, long timestampMs, int limit, boolean returnFacts) {
        String inserted = insertAt(factsJson, timestampMs);
        if (!inserted.startsWith("{\"ok\":true")) return inserted;
        return Runner.fireAndReport(session, recorder, runner.types(), limit, returnFacts);
    }

    /** Inserts facts stamped with {@code timestampMs}: the clock first advances to it (never back). */
    public synchronized String insertAt(String factsJson, long timestampMs) {
        List<Object> facts = new ArrayList<Object>();
        String error = Runner.buildFacts(runner.types(), factsJson, facts);
        if (error != null) return error;
        for (Object f : facts) {
            if (runner.types().isEvent(f)) continue;  // events are not kept by id
            String id = runner.types().idOf(f);
            if (id != null && byId.containsKey(id)) {
                return Runner.factError(facts.indexOf(f), null, "id", id,
                        "a fact with id '" + id + "' is already in the session: update or retract it");
            }
        }
        if (timestampMs != Long.MIN_VALUE) advanceTo(timestampMs);
        StringBuilder ids = new StringBuilder("{\"ok\":true,\"inserted\":").append(facts.size()).append('}');
        for (Object f : facts) {
            FactHandle h = session.insert(f);
            if (runner.types().isEvent(f)) continue;
            String id = runner.types().idOf(f);
            if (id != null) byId.put(id, h);
        }
        return ids.toString();
    }

    /** Replaces the fact with the same "id" by the given one (a JSON object). */
    public synchronized String update(String factJson) {
        List<Object> facts = new ArrayList<Object>();
        String error = Runner.buildFacts(runner.types(), "[" + factJson + "]", facts);
        if (error != null) return error;
        Object f = facts.get(0);
        String id = runner.types().idOf(f);
        FactHandle h = id == null ? null : byId.get(id);
        if (h == null) return Runner.factError(0, null, "id", id, "no fact with id '" + id + "' in the session");
        session.update(h, f);
        return "{\"ok\":true}";
    }

    /** Removes the fact with this id. */
    public synchronized String retract(String id) {
        FactHandle h = byId.remove(id);
        if (h == null) return Runner.factError(-1, null, "id", id, "no fact with id '" + id + "' in the session");
        session.delete(h);
        return "{\"ok\":true}";
    }

    public synchronized long advanceTo(long timestampMs) {
        long now = clock.getCurrentTime();
        if (timestampMs > now) clock.advanceTime(timestampMs - now, TimeUnit.MILLISECONDS);
        return clock.getCurrentTime();
    }

    public synchronized long advanceBy(long ms) {
        if (ms > 0) clock.advanceTime(ms, TimeUnit.MILLISECONDS);
        return clock.getCurrentTime();
    }

    public synchronized long now() { return clock.getCurrentTime(); }

    public synchronized long factCount() { return session.getFactCount(); }

    /** Fires what is activated; the result holds the actions and firings since the last fire. */
    public synchronized String fire(int limit, boolean returnFacts) {
        return Runner.fireAndReport(session, recorder, runner.types(), limit, returnFacts);
    }

    /** Inserts a batch and fires once; returns the number of firings (throughput path). */
    public synchronized int insertAndFireCount(String factsJson, int limit) {
        List<Object> facts = new ArrayList<Object>();
        String error = Runner.buildFacts(runner.types(), factsJson, facts);
        if (error != null) throw new IllegalArgumentException(error);
        for (Object f : facts) session.insert(f);
        int n = session.fireAllRules(limit);
        actions.drain();
        recorder.reset();
        return n;
    }

    public synchronized void dispose() { session.dispose(); }
}
