package org.printeps.gateway;

import java.nio.ByteBuffer;
import java.nio.charset.StandardCharsets;
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
        String error = insertFacts(factsJson, timestampMs);
        if (error != null) return error;
        return Runner.fireAndReport(session, recorder, runner.types(), limit, returnFacts);
    }

    /** Inserts facts stamped with {@code timestampMs}: the clock first advances to it (never back). */
    public synchronized String insertAt(String factsJson, long timestampMs) {
        String error = insertFacts(factsJson, timestampMs);
        if (error != null) return error;
        return "{\"ok\":true,\"inserted\":" + lastInserted + "}";
    }

    private int lastInserted;

    /** Builds and inserts the facts; returns the error answer, or null (count in lastInserted). */
    private String insertFacts(String factsJson, long timestampMs) {
        List<Object> facts = new ArrayList<Object>(4);
        String error = Runner.buildFacts(runner.types(), factsJson, facts);
        if (error != null) return error;
        TypeRegistry types = runner.types();
        for (int k = 0; k < facts.size(); k++) {
            Object f = facts.get(k);
            if (types.isEvent(f)) continue;  // events are not kept by id
            String id = types.idOf(f);
            if (id != null && byId.containsKey(id)) {
                return Runner.factError(k, null, "id", id,
                        "a fact with id '" + id + "' is already in the session: update or retract it");
            }
        }
        if (timestampMs != Long.MIN_VALUE) advanceTo(timestampMs);
        for (Object f : facts) {
            FactHandle h = session.insert(f);
            if (types.isEvent(f)) continue;
            String id = types.idOf(f);
            if (id != null) byId.put(id, h);
        }
        lastInserted = facts.size();
        return null;
    }

    private ByteBuffer inBuffer;
    private ByteBuffer outBuffer;
    private String overflow;

    /**
     * Shares two direct buffers with the caller (JPype wraps Python bytearrays): {@link #pushBuffered}
     * then reads the facts' UTF-8 JSON from {@code in} and writes its answer to {@code out}, so the
     * per-event call crosses JPype with numbers only (no String conversion either way).
     */
    public synchronized void attachBuffers(ByteBuffer in, ByteBuffer out) {
        this.inBuffer = in;
        this.outBuffer = out;
    }

    /**
     * {@link #pushAt} with the facts in the first {@code length} bytes of the input buffer. Returns
     * the answer's length in the output buffer, or -1 when it did not fit (then {@link #takeOverflow}
     * hands it over as a String).
     */
    public synchronized int pushBuffered(int length, long timestampMs, int limit, boolean returnFacts) {
        byte[] bytes = new byte[length];
        inBuffer.get(0, bytes, 0, length);
        String answer = pushAt(new String(bytes, StandardCharsets.UTF_8), timestampMs, limit, returnFacts);
        byte[] out = answer.getBytes(StandardCharsets.UTF_8);
        if (out.length > outBuffer.capacity()) {
            overflow = answer;
            return -1;
        }
        outBuffer.put(0, out, 0, out.length);
        return out.length;
    }

    /** The answer of the last {@link #pushBuffered} that did not fit its buffer. */
    public synchronized String takeOverflow() {
        String s = overflow;
        overflow = null;
        return s;
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
        recorder.reset();  // forgets the firings and the recorded actions
        return n;
    }

    /** Runs a DRL {@code query} with positional arguments (a JSON list); rows keyed by identifier. */
    public synchronized String query(String name, String argsJson) {
        Object parsed;
        try {
            parsed = Json.parse(argsJson);
        } catch (Json.ParseException e) {
            return Runner.factError(-1, null, "arguments", null, "query arguments are not valid JSON: " + e.getMessage());
        }
        if (!(parsed instanceof List)) return Runner.factError(-1, null, "arguments", null, "query arguments must be a JSON list");
        Object[] args = ((List<?>) parsed).toArray();
        try {
            Class<?>[] types = queryParameterTypes(name);
            for (int k = 0; types != null && k < args.length && k < types.length; k++) {
                args[k] = runner.types().convertValue("argument " + k, types[k], args[k]);
            }
        } catch (TypeRegistry.FactProblem p) {
            return Runner.factError(-1, null, "arguments", name, "query '" + name + "': " + p.getMessage());
        }
        org.kie.api.runtime.rule.QueryResults results;
        try {
            results = session.getQueryResults(name, args);
        } catch (RuntimeException e) {
            return Runner.factError(-1, null, "query", name, "query '" + name + "' failed: " + Runner.rootMessage(e));
        }
        String[] ids = results.getIdentifiers();
        StringBuilder b = new StringBuilder("{\"ok\":true,\"identifiers\":");
        Json.write(b, java.util.Arrays.asList(ids), null);
        b.append(",\"rows\":[");
        boolean first = true;
        for (org.kie.api.runtime.rule.QueryResultsRow row : results) {
            if (!first) b.append(',');
            first = false;
            b.append('{');
            for (int k = 0; k < ids.length; k++) {
                if (k > 0) b.append(',');
                Json.quote(b, ids[k]);
                b.append(':');
                Json.write(b, row.get(ids[k]), runner.types());
            }
            b.append('}');
        }
        return b.append("]}").toString();
    }

    /** The declared parameter types of a query (JSON numbers must become the declared int/long/...). */
    private Class<?>[] queryParameterTypes(String name) {
        for (org.kie.api.definition.KiePackage p : session.getKieBase().getKiePackages()) {
            for (org.kie.api.definition.rule.Query q : p.getQueries()) {
                if (q.getName().equals(name) && q instanceof org.drools.core.definitions.rule.impl.QueryImpl) {
                    org.drools.core.rule.Declaration[] ds = ((org.drools.core.definitions.rule.impl.QueryImpl) q).getParameters();
                    Class<?>[] out = new Class<?>[ds.length];
                    for (int k = 0; k < ds.length; k++) out[k] = ds[k].getDeclarationClass();
                    return out;
                }
            }
        }
        return null;
    }

    /** Sets a global declared by the rule set (not {@code actions}: that one is the gateway's). */
    public synchronized String setGlobal(String name, String valueJson) {
        if ("actions".equals(name)) {
            return Runner.factError(-1, null, "identifier", name, "the global 'actions' belongs to the gateway and cannot be set");
        }
        String typeName = null;
        for (org.kie.api.definition.KiePackage p : session.getKieBase().getKiePackages()) {
            for (org.kie.api.definition.rule.Global g : p.getGlobalVariables()) if (g.getName().equals(name)) typeName = g.getType();
        }
        if (typeName == null) return Runner.factError(-1, null, "identifier", name, "the rule set declares no global '" + name + "'");
        try {
            Object value = Json.parse(valueJson);
            Class<?> type = runner.types().declaredClass(typeName);
            if (type == null) type = Class.forName(typeName, false, Session.class.getClassLoader());
            session.setGlobal(name, runner.types().convertValue(name, type, value));
        } catch (TypeRegistry.FactProblem p) {
            return Runner.factError(-1, null, "object", name, "global '" + name + "': " + p.getMessage());
        } catch (Exception e) {
            return Runner.factError(-1, null, "object", name, "global '" + name + "': " + Runner.rootMessage(e));
        }
        return "{\"ok\":true}";
    }

    /** The value of a global, as JSON. */
    public synchronized String getGlobal(String name) {
        StringBuilder b = new StringBuilder("{\"ok\":true,\"value\":");
        Object v = "actions".equals(name) ? null : session.getGlobals().get(name);
        Json.write(b, v, runner.types());
        return b.append('}').toString();
    }

    public synchronized void dispose() { session.dispose(); }
}
