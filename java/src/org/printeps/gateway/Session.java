package org.printeps.gateway;

import java.nio.ByteBuffer;
import java.nio.charset.StandardCharsets;
import java.util.ArrayList;
import java.util.HashMap;
import java.util.List;
import java.util.Map;
import java.util.concurrent.TimeUnit;

import org.kie.api.runtime.KieSession;
import org.kie.api.runtime.rule.AgendaFilter;
import org.kie.api.runtime.rule.FactHandle;
import org.kie.api.time.SessionClock;
import org.kie.api.time.SessionPseudoClock;

/**
 * A long-lived stateful session: facts stay between calls. For event streams, events carry their
 * own timestamps and drive a pseudo clock, so replaying recorded data gives the same answers; for
 * KIE Server / REST conversations, {@link #execute} runs command batches with real fact handles
 * (see {@link Batch}, {@link Handles}), and {@link #moveFrom} carries a session to a new rule set
 * version. All methods are synchronized: a KieSession is not thread-safe.
 */
public final class Session {
    final Runner runner;
    final KieSession session;
    private final Actions actions = new Actions();
    final Recorder recorder;
    final SessionClock clock;
    final Map<String, FactHandle> byId = new HashMap<String, FactHandle>();
    /** Fact handles by their external form (sessions that answer commands; null for stream sessions). */
    final Handles handles;
    /** Refraction carried over a move to a new version or a restore, until it is spent (see Refraction). */
    Refraction refraction;
    boolean disposed;
    /** Time limit of each fire in ms (0: none), see {@link Watchdog}. */
    private volatile long fireTimeoutMs;

    public Session(Runner runner, boolean recordFacts) {
        this(runner, recordFacts, false, false);
    }

    /**
     * A session with a {@code realtime} (else pseudo) clock; {@code trackHandles} keeps the fact
     * handle registry that {@link #execute}'s commands resolve handles with.
     */
    public Session(Runner runner, boolean recordFacts, boolean realtime, boolean trackHandles) {
        this.runner = runner;
        this.recordFacts = recordFacts;
        this.session = runner.newSession(realtime);
        if (Runner.declaresGlobal(session.getKieBase(), "actions")) session.setGlobal("actions", actions);
        this.recorder = new Recorder(actions, runner.types(), recordFacts);
        session.addEventListener(recorder);
        this.clock = session.getSessionClock();
        this.handles = trackHandles ? new Handles() : null;
        if (handles != null) session.addEventListener(handles);
    }

    private final boolean recordFacts;

    /**
     * A fresh, empty session like this one: the same compiled version, clock kind, handle registry
     * and fire time limit (what a snapshot taken with matches pending is restored into).
     */
    public Session twin() {
        Session twin = new Session(runner, recordFacts, realtime(), handles != null);
        twin.setFireTimeoutMs(fireTimeoutMs);
        return twin;
    }

    /** Sets the time limit of this session's fires ({@code engine.fire_timeout_s}; 0: none). */
    public void setFireTimeoutMs(long timeoutMs) { this.fireTimeoutMs = timeoutMs; }

    /** Runs a batch of commands (a JSON list, see {@link Batch}); the answer is JSON. */
    public synchronized String execute(String commandsJson, int fireLimit) {
        if (disposed) return "{\"ok\":false,\"index\":-1,\"op\":null,\"kind\":\"disposed\",\"field\":null,"
                + "\"message\":\"the session is disposed\",\"applied\":false,\"disposed\":true}";
        return new Batch(this, fireLimit).run(commandsJson);
    }

    /** The live handle a handle's text names (KIE's external form), or Handles.Stale. */
    FactHandle resolve(String text) throws Handles.Stale {
        if (handles != null) return handles.resolve(text);
        Handles scan = new Handles();
        for (FactHandle h : Handles.all(session)) scan.objectInserted(new InsertedEvent(h));
        return scan.resolve(text);
    }

    /** A minimal event to feed a scan-only registry (stream sessions keep none). */
    private static final class InsertedEvent implements org.kie.api.event.rule.ObjectInsertedEvent {
        private final FactHandle h;
        InsertedEvent(FactHandle h) { this.h = h; }
        public FactHandle getFactHandle() { return h; }
        public Object getObject() { return DroolsInternals.objectOf(h); }
        public org.kie.api.definition.rule.Rule getRule() { return null; }
        public org.kie.api.runtime.KieRuntime getKieRuntime() { return null; }
    }

    /**
     * One fire of a batch: {@code max > 0} fires at most that many rules (KIE's
     * {@code fire-all-rules max}, no runaway report); otherwise up to {@code limit} with the
     * runaway guard. Moves' refraction applies until a fire leaves the agenda empty.
     */
    String fireForBatch(int max, int limit) {
        if (max == 0) {  // fireAllRules(0): nothing fires
            StringBuilder b = new StringBuilder(64);
            recorder.writeSuccess(b, 0);
            return b.append('}').toString();
        }
        if (max > 0) {
            AgendaFilter filter = refraction;
            int n;
            Watchdog.Watch watch = Watchdog.watch(session, fireTimeoutMs);
            try {
                n = filter == null ? session.fireAllRules(max) : session.fireAllRules(filter, max);
                if (watch != null && watch.halted) {
                    recorder.reset();
                    return Runner.timeoutError(fireTimeoutMs, n);
                }
            } catch (org.kie.api.runtime.rule.ConsequenceException ce) {
                recorder.reset();
                return Runner.runtimeError(ce.getMatch() == null ? null : ce.getMatch().getRule().getName(), Runner.rootMessage(ce));
            } catch (RuntimeException re) {
                recorder.reset();
                return Runner.runtimeError(null, Runner.rootMessage(re));
            } finally {
                Watchdog.release(watch);
            }
            afterFire(n < max);
            StringBuilder b = new StringBuilder(256);
            recorder.writeSuccess(b, n);
            return b.append('}').toString();
        }
        String answer = Runner.fireAndReport(session, recorder, runner.types(), limit, false, refraction, fireTimeoutMs);
        afterFire(true);
        return answer;
    }

    /**
     * After a fire: the refraction carried in is dropped once spent, or once a full fire emptied
     * the agenda of a rule base without agenda groups (no match it could still drop is left).
     */
    private void afterFire(boolean emptied) {
        if (refraction != null && (refraction.spent() || (emptied && !hasAgendaGroups()))) {
            refraction.detach();
            refraction = null;
        }
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
        String answer = Runner.fireAndReport(session, recorder, runner.types(), limit, returnFacts, refraction, fireTimeoutMs);
        afterFire(true);
        return answer;
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
        if (timestampMs > now && clock instanceof SessionPseudoClock) {
            ((SessionPseudoClock) clock).advanceTime(timestampMs - now, TimeUnit.MILLISECONDS);
        }
        return clock.getCurrentTime();
    }

    public synchronized long advanceBy(long ms) {
        if (ms > 0 && clock instanceof SessionPseudoClock) ((SessionPseudoClock) clock).advanceTime(ms, TimeUnit.MILLISECONDS);
        return clock.getCurrentTime();
    }

    public boolean realtime() { return !(clock instanceof SessionPseudoClock); }

    public synchronized long now() { return clock.getCurrentTime(); }

    public synchronized long factCount() { return session.getFactCount(); }

    /** Fires what is activated; the result holds the actions and firings since the last fire. */
    public synchronized String fire(int limit, boolean returnFacts) {
        String answer = Runner.fireAndReport(session, recorder, runner.types(), limit, returnFacts, refraction, fireTimeoutMs);
        afterFire(true);
        return answer;
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
        String[] error = new String[1];
        List<?> parsed = jsonList(argsJson, "arguments", "query arguments", error);
        if (parsed == null) return error[0];
        Object[] args = parsed.toArray();
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
        writeRows(b, results, Integer.MAX_VALUE);
        return b.append("]}").toString();
    }

    /**
     * Runs several queries without arguments in one call, at most {@code maxRows} rows each:
     * {"ok":true,"results":{name:[rows]}}. Why: an explanation asks dozens of diagnostic queries,
     * and one call each cost more than the queries themselves.
     */
    public synchronized String queries(String namesJson, int maxRows) {
        String[] error = new String[1];
        List<?> parsed = jsonList(namesJson, "queries", "query names", error);
        if (parsed == null) return error[0];
        StringBuilder b = new StringBuilder("{\"ok\":true,\"results\":{");
        boolean first = true;
        for (Object item : parsed) {
            String name = String.valueOf(item);
            org.kie.api.runtime.rule.QueryResults results;
            try {
                results = session.getQueryResults(name);
            } catch (RuntimeException e) {
                return Runner.factError(-1, null, "query", name, "query '" + name + "' failed: " + Runner.rootMessage(e));
            }
            if (!first) b.append(',');
            first = false;
            Json.quote(b, name);
            b.append(":[");
            writeRows(b, results, maxRows);
            b.append(']');
        }
        return b.append("}}").toString();
    }

    /** A JSON list argument ({@code field}, {@code what} for messages), or null with the refusal in {@code error[0]}. */
    private static List<?> jsonList(String json, String field, String what, String[] error) {
        try {
            Object parsed = Json.parse(json);
            if (parsed instanceof List) return (List<?>) parsed;
            error[0] = Runner.factError(-1, null, field, null, what + " must be a JSON list");
        } catch (Json.ParseException e) {
            error[0] = Runner.factError(-1, null, field, null, what + " are not valid JSON: " + e.getMessage());
        }
        return null;
    }

    private void writeRows(StringBuilder b, org.kie.api.runtime.rule.QueryResults results, int maxRows) {
        String[] ids = results.getIdentifiers();
        int n = 0;
        for (org.kie.api.runtime.rule.QueryResultsRow row : results) {
            if (n >= maxRows) break;
            if (n > 0) b.append(',');
            n++;
            b.append('{');
            for (int k = 0; k < ids.length; k++) {
                if (k > 0) b.append(',');
                Json.quote(b, ids[k]);
                b.append(':');
                Json.write(b, row.get(ids[k]), runner.types());
            }
            b.append('}');
        }
    }

    /** " (its queries: a, b)" or " (it has none)", for messages. */
    String queryNames() {
        java.util.List<String> names = new java.util.ArrayList<String>();
        for (org.kie.api.definition.KiePackage p : session.getKieBase().getKiePackages()) {
            for (org.kie.api.definition.rule.Query q : p.getQueries()) names.add(q.getName());
        }
        java.util.Collections.sort(names);
        return names.isEmpty() ? " (it has none)" : " (its queries: " + String.join(", ", names) + ")";
    }

    /** The declared parameter types of a query (JSON numbers must become the declared int/long/...). */
    Class<?>[] queryParameterTypes(String name) {
        for (org.kie.api.definition.KiePackage p : session.getKieBase().getKiePackages()) {
            for (org.kie.api.definition.rule.Query q : p.getQueries()) {
                if (q.getName().equals(name)) {
                    Class<?>[] out = DroolsInternals.queryParameterTypes(q);
                    if (out != null) return out;
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

    public synchronized void dispose() {
        if (!disposed) {
            disposed = true;
            session.dispose();
        }
    }

    public synchronized boolean isDisposed() { return disposed; }

    // ------------------------------------------------------------------ moving to a new version

    /**
     * Takes over {@code old}'s state, as {@code KieContainer.updateToVersion} does for a live
     * session: its facts (re-built as this version's types, into the same entry points), the clock
     * (a pseudo clock is advanced to the old one's time), its globals but {@code actions}, the
     * agenda-group focus stack and the fact handles clients hold (kept as aliases). Matches the old session had
     * already fired do not fire again (see {@link Refraction}: {@code unchangedRulesJson} lists the
     * rules whose text is the same in both versions). Call on a fresh session; {@code old} is
     * left as it was unless the move succeeds, and must then be disposed by the caller.
     * Returns {"ok":true,"facts":n} or {"ok":false,"message":...} naming the fact that does not fit.
     */
    public synchronized String moveFrom(Session old, String unchangedRulesJson) {
        synchronized (old) {
            return Carry.move(this, old, unchangedRulesJson);
        }
    }

    // ------------------------------------------------------------------ durable sessions (snapshot, restore)

    /**
     * The session's state as JSON, for a durable session's snapshot: its facts in insertion order
     * (each with its entry point and every "id:hash" text clients may hold for it), the clock, the
     * globals but {@code actions}, and the agenda-group focus stack (bottom to top; {@code focus} is
     * its top). Reads only (queued {@code setFocus} pushes are applied first); what is pending on the agenda
     * is {@link #takePending}'s. Returns {"ok":false,"message"} naming a fact that cannot be written.
     */
    public synchronized String snapshot() { return Carry.snapshot(this); }

    /**
     * The matches pending on the agenda, in every agenda group, as a JSON list of keys naming facts
     * by their place in {@link #snapshot}'s list (taken right after it): with it, a snapshot can be
     * taken at any command boundary. The walk consumes them: this session must then be replaced
     * by one restored from the snapshot ({@link #restoreFacts} then {@link #refract}).
     */
    public synchronized String takePending() { return Carry.takePending(this); }

    /** Whether the rules name agenda groups besides MAIN (a full fire then leaves their matches pending). */
    public synchronized boolean hasAgendaGroups() {
        if (agendaGroups == null) agendaGroups = !DroolsInternals.agendaGroups(session.getKieBase()).isEmpty();
        return agendaGroups;
    }

    private Boolean agendaGroups;
    private Carry.Plan restoring;

    /**
     * Rebuilds a snapshot's state (see {@link #snapshot}) in this fresh session, then its
     * refraction: every match over the restored facts, in every agenda group, counts as fired but
     * the snapshot's {@code pending} ones (all, for a snapshot without that list, taken with nothing
     * left to fire). Checks everything first: a snapshot that does not fit this version changes
     * nothing and answers {"ok":false,"message"}.
     */
    public synchronized String restore(String snapshotJson) {
        String answer = restoreFacts(snapshotJson);
        if (restoring != null) {
            Carry.refract(this, restoring, restoring.pending);
            restoring = null;
        }
        return answer;
    }

    /**
     * The first half of {@link #restore}: the snapshot checked against this version (its facts,
     * entry points and globals), nothing changed yet; {@link #refract} then restores it (with the
     * pending matches taken from the session the snapshot was read from, once this half succeeded).
     */
    public synchronized String restoreFacts(String snapshotJson) {
        if (disposed) return Carry.problem("the session is disposed");
        StringBuilder answer = new StringBuilder();
        restoring = Carry.restoreFacts(this, snapshotJson, answer);
        return answer.toString();
    }

    /** The second half of {@link #restore}: the checked state restored, with these pending matches (a JSON list of keys). */
    public synchronized void refract(String pendingJson) {
        if (restoring == null) return;
        Carry.refract(this, restoring, Json.parse(pendingJson));
        restoring = null;
    }

    /**
     * Makes {@code oldText} (a handle a client holds, from before a rebuild) an alias of the fact
     * {@code nowText} names here: a durable session's replayed insert gets a new handle.
     */
    public synchronized String alias(String oldText, String nowText) {
        if (handles == null) return Carry.problem("this session keeps no fact handles");
        try {
            FactHandle now = handles.resolve(nowText);
            String[] parts = oldText.trim().split(":");
            handles.alias(Long.parseLong(parts[1]), Integer.parseInt(parts[2]), now);
            return "{\"ok\":true}";
        } catch (Handles.Stale e) {
            return Carry.problem(e.getMessage());
        } catch (RuntimeException e) {
            return Carry.problem("'" + oldText + "' is not a fact handle: " + Runner.rootMessage(e));
        }
    }

    /** The external form of the live handle {@code text} names now (an update changes it), or null. */
    public synchronized String currentHandle(String text) {
        try {
            return Handles.external(resolve(text));
        } catch (Handles.Stale e) {
            return null;
        }
    }
}
