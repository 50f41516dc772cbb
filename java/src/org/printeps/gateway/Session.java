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
    private final Recorder recorder;
    final SessionClock clock;
    private final Map<String, FactHandle> byId = new HashMap<String, FactHandle>();
    /** Fact handles by their external form (sessions that answer commands; null for stream sessions). */
    private final Handles handles;
    /** Refraction carried over a move to a new version, until a fire empties the agenda (see Refraction). */
    private Refraction refraction;
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
        this.session = runner.newSession(realtime);
        if (Runner.declaresGlobal(session.getKieBase(), "actions")) session.setGlobal("actions", actions);
        this.recorder = new Recorder(actions, runner.types(), recordFacts);
        session.addEventListener(recorder);
        this.clock = session.getSessionClock();
        this.handles = trackHandles ? new Handles() : null;
        if (handles != null) session.addEventListener(handles);
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
            if (n < max) refraction = null;
            StringBuilder b = new StringBuilder(256);
            recorder.writeSuccess(b, n);
            return b.append('}').toString();
        }
        String answer = Runner.fireAndReport(session, recorder, runner.types(), limit, false, refraction, fireTimeoutMs);
        refraction = null;
        return answer;
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
        refraction = null;
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
        refraction = null;
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
        writeRows(b, results, Integer.MAX_VALUE);
        return b.append("]}").toString();
    }

    /**
     * Runs several queries without arguments in one call, at most {@code maxRows} rows each:
     * {"ok":true,"results":{name:[rows]}}. Why: an explanation asks dozens of diagnostic queries,
     * and one call each cost more than the queries themselves.
     */
    public synchronized String queries(String namesJson, int maxRows) {
        Object parsed;
        try {
            parsed = Json.parse(namesJson);
        } catch (Json.ParseException e) {
            return Runner.factError(-1, null, "queries", null, "query names are not valid JSON: " + e.getMessage());
        }
        if (!(parsed instanceof List)) return Runner.factError(-1, null, "queries", null, "query names must be a JSON list");
        StringBuilder b = new StringBuilder("{\"ok\":true,\"results\":{");
        boolean first = true;
        for (Object item : (List<?>) parsed) {
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
     * agenda focus and the fact handles clients hold (kept as aliases). Matches the old session had
     * already fired do not fire again (see {@link Refraction}: {@code unchangedRulesJson} lists the
     * rules whose text is the same in both versions). Call on a fresh session; {@code old} is
     * left as it was unless the move succeeds, and must then be disposed by the caller.
     * Returns {"ok":true,"facts":n} or {"ok":false,"message":...} naming the fact that does not fit.
     */
    public synchronized String moveFrom(Session old, String unchangedRulesJson) {
        synchronized (old) {
            if (old.disposed) return "{\"ok\":false,\"message\":\"the session to move is disposed\"}";
            TypeRegistry mine = runner.types();
            TypeRegistry theirs = old.runner.types();
            List<FactHandle> oldHandles = Handles.all(old.session);
            List<Object> built = new ArrayList<Object>(oldHandles.size());
            List<org.kie.api.runtime.rule.EntryPoint> targets = new ArrayList<org.kie.api.runtime.rule.EntryPoint>();
            for (FactHandle h : oldHandles) {
                Object fact = DroolsInternals.objectOf(h);
                if (fact instanceof Actions) { built.add(null); targets.add(null); continue; }
                StringBuilder json = new StringBuilder();
                if (!theirs.writeFact(json, fact)) {
                    return problem("fact " + Handles.external(h) + " is not of a declared type (" + fact.getClass().getName() + ")");
                }
                @SuppressWarnings("unchecked")
                Map<String, Object> values = (Map<String, Object>) Json.parse(json.toString());
                String type = String.valueOf(values.get("type"));
                TypeRegistry.TypeInfo info = mine.type(type);
                if (info == null) return problem("fact " + Handles.external(h) + ": the new version declares no type " + type);
                try {
                    built.add(mine.build(info, values, 0));
                } catch (TypeRegistry.FactProblem p) {
                    return problem("fact " + Handles.external(h) + " (" + type + ") does not fit the new version: " + p.getMessage());
                }
                org.kie.api.runtime.rule.EntryPoint ep = session.getEntryPoint(DroolsInternals.entryPointName(h));
                if (ep == null) return problem("fact " + Handles.external(h) + ": the new version has no entry point " + DroolsInternals.entryPointName(h));
                targets.add(ep);
            }
            Map<String, Object> globals = new java.util.LinkedHashMap<String, Object>();
            for (org.kie.api.definition.KiePackage p : session.getKieBase().getKiePackages()) {
                for (org.kie.api.definition.rule.Global g : p.getGlobalVariables()) {
                    if (g.getName().equals("actions")) continue;
                    Object v = old.session.getGlobals().get(g.getName());
                    if (v == null) continue;
                    StringBuilder json = new StringBuilder();
                    Json.write(json, v, theirs);
                    try {
                        Class<?> type = mine.declaredClass(g.getType());
                        if (type == null) type = Class.forName(g.getType(), false, Session.class.getClassLoader());
                        globals.put(g.getName(), mine.convertValue(g.getName(), type, Json.parse(json.toString())));
                    } catch (Exception e) {
                        return problem("global '" + g.getName() + "' does not fit the new version: " + Runner.rootMessage(e));
                    }
                }
            }
            // the state fits: from here on nothing can refuse
            if (clock instanceof SessionPseudoClock) advanceTo(old.clock.getCurrentTime());
            for (Map.Entry<String, Object> g : globals.entrySet()) session.setGlobal(g.getKey(), g.getValue());
            Map<Object, Object> mapped = new java.util.IdentityHashMap<Object, Object>();
            java.util.Set<Object> unchanged = java.util.Collections.newSetFromMap(new java.util.IdentityHashMap<Object, Boolean>());
            Map<String, FactHandle> oldAliases = old.handles == null ? new HashMap<String, FactHandle>() : old.handles.aliasHandles();
            Map<FactHandle, FactHandle> moved = new java.util.IdentityHashMap<FactHandle, FactHandle>();
            int count = 0;
            for (int k = 0; k < oldHandles.size(); k++) {
                Object fact = built.get(k);
                if (fact == null) continue;
                FactHandle nh = targets.get(k).insert(fact);
                FactHandle oh = oldHandles.get(k);
                moved.put(oh, nh);
                mapped.put(DroolsInternals.objectOf(oh), fact);
                unchanged.add(fact);
                String id = theirs.idOf(DroolsInternals.objectOf(oh));
                if (id != null && !types().isEvent(fact)) byId.put(id, nh);
                if (handles != null) handles.alias(DroolsInternals.handleId(oh), DroolsInternals.identityHashCode(oh), nh);
                count++;
            }
            if (handles != null) {
                for (Map.Entry<String, FactHandle> a : oldAliases.entrySet()) {
                    FactHandle nh = moved.get(a.getValue());
                    if (nh == null) continue;
                    String[] idHash = a.getKey().split(":");
                    handles.alias(Long.parseLong(idHash[0]), Integer.parseInt(idHash[1]), nh);
                }
                handles.setUnchangedSinceMove(unchanged);
            } else {
                session.addEventListener(new org.kie.api.event.rule.DefaultRuleRuntimeEventListener() {
                    @Override public void objectUpdated(org.kie.api.event.rule.ObjectUpdatedEvent e) {
                        unchanged.remove(e.getOldObject());
                        unchanged.remove(e.getObject());
                    }
                    @Override public void objectDeleted(org.kie.api.event.rule.ObjectDeletedEvent e) { unchanged.remove(e.getOldObject()); }
                });
            }
            // the old session's pending matches: recorded (and consumed: it is discarded after the move)
            final Map<String, Integer> pending = Refraction.emptyKeys();
            final Map<Object, Object> byOld = mapped;
            final java.util.Set<Object> cameAcross = unchanged;
            try {
                old.session.fireAllRules(match -> {
                    Refraction.add(pending, Refraction.key(match.getRule().getName(), match.getObjects(), byOld, cameAcross));
                    return false;
                });
            } catch (RuntimeException e) {
                // an agenda that cannot even be walked: its matches count as pending (they fire here)
            }
            old.recorder.reset();
            java.util.Set<String> unchangedRules = new java.util.HashSet<String>();
            Object parsed = Json.parse(unchangedRulesJson);
            if (parsed instanceof List) for (Object r : (List<?>) parsed) unchangedRules.add(String.valueOf(r));
            // what had fired: the new version's first agenda over the facts that came across, minus the pending
            Map<String, Integer> fired = firstAgenda(built, targets, globals, old, unchangedRules, cameAcross);
            Refraction.subtract(fired, pending);
            refraction = new Refraction(unchangedRules, unchanged, fired);
            String focus = DroolsInternals.focusName(old.session);
            if (focus != null && !focus.equals("MAIN")) session.getAgenda().getAgendaGroup(focus).setFocus();
            return "{\"ok\":true,\"facts\":" + count + "}";
        }
    }

    /**
     * The keys (see {@link Refraction#key}) of the matches of {@code rules} that the new version
     * holds over {@code built} before anything fires: found in a throwaway session of this version
     * (same facts, same entry points, clock, globals and focus), whose agenda is walked without
     * firing. This session's own agenda must not be walked: walking consumes the matches.
     */
    private Map<String, Integer> firstAgenda(List<Object> built, List<org.kie.api.runtime.rule.EntryPoint> targets,
                                              Map<String, Object> globals, Session old, java.util.Set<String> rules,
                                              java.util.Set<Object> facts) {
        final Map<String, Integer> keys = Refraction.emptyKeys();
        if (rules.isEmpty()) return keys;
        KieSession probe = runner.newSession(false);
        try {
            if (Runner.declaresGlobal(probe.getKieBase(), "actions")) probe.setGlobal("actions", new Actions());
            for (Map.Entry<String, Object> g : globals.entrySet()) probe.setGlobal(g.getKey(), g.getValue());
            SessionClock probeClock = probe.getSessionClock();
            long now = old.clock.getCurrentTime();
            if (probeClock instanceof SessionPseudoClock && now > probeClock.getCurrentTime()) {
                ((SessionPseudoClock) probeClock).advanceTime(now - probeClock.getCurrentTime(), TimeUnit.MILLISECONDS);
            }
            for (int k = 0; k < built.size(); k++) {
                if (built.get(k) == null) continue;
                probe.getEntryPoint(targets.get(k).getEntryPointId()).insert(built.get(k));
            }
            String focus = DroolsInternals.focusName(old.session);
            if (focus != null && !focus.equals("MAIN")) probe.getAgenda().getAgendaGroup(focus).setFocus();
            probe.fireAllRules(match -> {
                String rule = match.getRule().getName();
                if (rules.contains(rule)) Refraction.add(keys, Refraction.key(rule, match.getObjects(), null, facts));
                return false;
            });
        } catch (RuntimeException e) {
            // a probe that fails refracts nothing: every match fires again rather than one being lost
            keys.clear();
        } finally {
            probe.dispose();
        }
        return keys;
    }

    private TypeRegistry types() { return runner.types(); }

    private static String problem(String message) {
        StringBuilder b = new StringBuilder("{\"ok\":false,\"message\":");
        Json.quote(b, message);
        return b.append('}').toString();
    }

    // ------------------------------------------------------------------ durable sessions (snapshot, restore)

    /**
     * The session's state as JSON, for a durable session's snapshot: its facts in insertion order
     * (each with its entry point and every "id:hash" text clients may hold for it), the clock, the
     * globals but {@code actions}, and the agenda focus. Taken only when the agenda holds nothing
     * to fire (right after a full fire): {@link #restore} counts every match over these facts as
     * fired. Returns {"ok":false,"message"} naming a fact that cannot be written.
     */
    public synchronized String snapshot() {
        if (disposed) return problem("the session is disposed");
        TypeRegistry types = runner.types();
        StringBuilder b = new StringBuilder(4096).append("{\"ok\":true,\"time\":").append(clock.getCurrentTime());
        b.append(",\"facts\":[");
        boolean first = true;
        for (FactHandle h : Handles.all(session)) {
            Object fact = DroolsInternals.objectOf(h);
            if (fact instanceof Actions) continue;
            StringBuilder json = new StringBuilder();
            if (!types.writeFact(json, fact)) {
                return problem("fact " + Handles.external(h) + " is not of a declared type (" + fact.getClass().getName() + ")");
            }
            if (!first) b.append(',');
            first = false;
            b.append("{\"ep\":");
            Json.quote(b, DroolsInternals.entryPointName(h));
            b.append(",\"keys\":[");
            List<String> keys = handles != null ? handles.keysOf(h)
                    : java.util.Collections.singletonList(DroolsInternals.handleId(h) + ":" + DroolsInternals.identityHashCode(h));
            for (int k = 0; k < keys.size(); k++) {
                if (k > 0) b.append(',');
                Json.quote(b, keys.get(k));
            }
            b.append("],\"fact\":").append(json).append('}');
        }
        b.append("],\"globals\":{");
        first = true;
        for (org.kie.api.definition.KiePackage p : session.getKieBase().getKiePackages()) {
            for (org.kie.api.definition.rule.Global g : p.getGlobalVariables()) {
                if (g.getName().equals("actions")) continue;
                Object v = session.getGlobals().get(g.getName());
                if (v == null) continue;
                if (!first) b.append(',');
                first = false;
                Json.quote(b, g.getName());
                b.append(':');
                Json.write(b, v, types);
            }
        }
        b.append("},\"focus\":");
        String focus = DroolsInternals.focusName(session);
        Json.quote(b, focus == null ? "MAIN" : focus);
        return b.append('}').toString();
    }

    /**
     * Rebuilds a snapshot's state (see {@link #snapshot}) in this fresh session: the facts in
     * their order into their entry points, the pseudo clock, the globals, the focus, the handles
     * clients hold (as aliases), and refraction: every match over the restored facts counts as
     * fired (the snapshot was taken with nothing left to fire), until a fire empties the agenda,
     * as after {@link #moveFrom}. Checks everything first: a snapshot that does not fit this
     * version changes nothing and answers {"ok":false,"message"}.
     */
    public synchronized String restore(String snapshotJson) {
        if (disposed) return problem("the session is disposed");
        TypeRegistry mine = runner.types();
        Map<?, ?> snap;
        try {
            snap = (Map<?, ?>) Json.parse(snapshotJson);
        } catch (RuntimeException e) {
            return problem("the snapshot is not readable JSON: " + Runner.rootMessage(e));
        }
        if (snap == null || !(snap.get("facts") instanceof List) || !(snap.get("time") instanceof Number)) {
            return problem("the snapshot has no facts list or no time");
        }
        List<?> facts = (List<?>) snap.get("facts");
        List<Object> built = new ArrayList<Object>(facts.size());
        List<org.kie.api.runtime.rule.EntryPoint> targets = new ArrayList<org.kie.api.runtime.rule.EntryPoint>();
        for (int k = 0; k < facts.size(); k++) {
            if (!(facts.get(k) instanceof Map) || !(((Map<?, ?>) facts.get(k)).get("fact") instanceof Map)) {
                return problem("snapshot fact " + k + " is not an object with a fact");
            }
            Map<?, ?> f = (Map<?, ?>) facts.get(k);
            Map<?, ?> values = (Map<?, ?>) f.get("fact");
            String type = String.valueOf(values.get("type"));
            TypeRegistry.TypeInfo info = mine.type(type);
            if (info == null) return problem("snapshot fact " + k + ": the version declares no type " + type);
            try {
                built.add(mine.build(info, values, 0));
            } catch (TypeRegistry.FactProblem p) {
                return problem("snapshot fact " + k + " (" + type + ") does not fit the version: " + p.getMessage());
            }
            org.kie.api.runtime.rule.EntryPoint ep = session.getEntryPoint(String.valueOf(f.get("ep")));
            if (ep == null) return problem("snapshot fact " + k + ": the version has no entry point " + f.get("ep"));
            targets.add(ep);
        }
        Map<String, Object> globals = new java.util.LinkedHashMap<String, Object>();
        Map<?, ?> savedGlobals = snap.get("globals") instanceof Map ? (Map<?, ?>) snap.get("globals") : new HashMap<String, Object>();
        for (org.kie.api.definition.KiePackage p : session.getKieBase().getKiePackages()) {
            for (org.kie.api.definition.rule.Global g : p.getGlobalVariables()) {
                if (g.getName().equals("actions") || !savedGlobals.containsKey(g.getName())) continue;
                try {
                    Class<?> type = mine.declaredClass(g.getType());
                    if (type == null) type = Class.forName(g.getType(), false, Session.class.getClassLoader());
                    globals.put(g.getName(), mine.convertValue(g.getName(), type, savedGlobals.get(g.getName())));
                } catch (Exception e) {
                    return problem("global '" + g.getName() + "' does not fit the version: " + Runner.rootMessage(e));
                }
            }
        }
        // the state fits: from here on nothing can refuse
        long now = ((Number) snap.get("time")).longValue();
        if (clock instanceof SessionPseudoClock) advanceTo(now);
        for (Map.Entry<String, Object> g : globals.entrySet()) session.setGlobal(g.getKey(), g.getValue());
        java.util.Set<Object> restored = java.util.Collections.newSetFromMap(new java.util.IdentityHashMap<Object, Boolean>());
        for (int k = 0; k < built.size(); k++) {
            Object fact = built.get(k);
            FactHandle nh = targets.get(k).insert(fact);
            restored.add(fact);
            String id = mine.idOf(fact);
            if (id != null && !mine.isEvent(fact)) byId.put(id, nh);
            Object keys = ((Map<?, ?>) facts.get(k)).get("keys");
            if (handles != null && keys instanceof List) {
                for (Object key : (List<?>) keys) {
                    String[] idHash = String.valueOf(key).split(":");
                    if (idHash.length != 2) continue;
                    try {
                        handles.alias(Long.parseLong(idHash[0]), Integer.parseInt(idHash[1]), nh);
                    } catch (NumberFormatException e) {
                        // a key that is no "id:hash" names no handle a client can hold
                    }
                }
            }
        }
        if (handles != null) handles.setUnchangedSinceMove(restored);
        java.util.Set<String> rules = new java.util.HashSet<String>();
        for (org.kie.api.definition.KiePackage p : session.getKieBase().getKiePackages()) {
            for (org.kie.api.definition.rule.Rule r : p.getRules()) rules.add(r.getName());
        }
        String focus = snap.get("focus") == null ? "MAIN" : String.valueOf(snap.get("focus"));
        Map<String, Integer> fired = probeAgenda(built, targets, globals, now, focus, rules, restored);
        refraction = new Refraction(rules, restored, fired);
        if (!focus.equals("MAIN")) session.getAgenda().getAgendaGroup(focus).setFocus();
        recorder.reset();
        return "{\"ok\":true,\"facts\":" + built.size() + "}";
    }

    /**
     * Makes {@code oldText} (a handle a client holds, from before a rebuild) an alias of the fact
     * {@code nowText} names here: a durable session's replayed insert gets a new handle.
     */
    public synchronized String alias(String oldText, String nowText) {
        if (handles == null) return problem("this session keeps no fact handles");
        try {
            FactHandle now = handles.resolve(nowText);
            String[] parts = oldText.trim().split(":");
            handles.alias(Long.parseLong(parts[1]), Integer.parseInt(parts[2]), now);
            return "{\"ok\":true}";
        } catch (Handles.Stale e) {
            return problem(e.getMessage());
        } catch (RuntimeException e) {
            return problem("'" + oldText + "' is not a fact handle: " + Runner.rootMessage(e));
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

    /**
     * The keys of the matches of {@code rules} over {@code built} before anything fires, found in
     * a throwaway session of this version (see {@link #firstAgenda}; this one takes the clock and
     * focus as values, for a restore that has no old session).
     */
    private Map<String, Integer> probeAgenda(List<Object> built, List<org.kie.api.runtime.rule.EntryPoint> targets,
                                             Map<String, Object> globals, long now, String focus,
                                             java.util.Set<String> rules, java.util.Set<Object> facts) {
        final Map<String, Integer> keys = Refraction.emptyKeys();
        if (rules.isEmpty() || built.isEmpty()) return keys;
        KieSession probe = runner.newSession(false);
        try {
            if (Runner.declaresGlobal(probe.getKieBase(), "actions")) probe.setGlobal("actions", new Actions());
            for (Map.Entry<String, Object> g : globals.entrySet()) probe.setGlobal(g.getKey(), g.getValue());
            SessionClock probeClock = probe.getSessionClock();
            if (probeClock instanceof SessionPseudoClock && now > probeClock.getCurrentTime()) {
                ((SessionPseudoClock) probeClock).advanceTime(now - probeClock.getCurrentTime(), TimeUnit.MILLISECONDS);
            }
            for (int k = 0; k < built.size(); k++) probe.getEntryPoint(targets.get(k).getEntryPointId()).insert(built.get(k));
            if (focus != null && !focus.equals("MAIN")) probe.getAgenda().getAgendaGroup(focus).setFocus();
            probe.fireAllRules(match -> {
                String rule = match.getRule().getName();
                if (rules.contains(rule)) Refraction.add(keys, Refraction.key(rule, match.getObjects(), null, facts));
                return false;
            });
        } catch (RuntimeException e) {
            keys.clear();  // a probe that fails refracts nothing: matches fire again rather than one being lost
        } finally {
            probe.dispose();
        }
        return keys;
    }
}
