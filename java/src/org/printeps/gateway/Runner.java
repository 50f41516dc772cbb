package org.printeps.gateway;

import java.util.ArrayList;
import java.util.Collection;
import java.util.List;
import java.util.Map;

import org.kie.api.KieBase;
import org.kie.api.KieServices;
import org.kie.api.definition.KiePackage;
import org.kie.api.definition.rule.Global;
import org.kie.api.runtime.KieSession;
import org.kie.api.runtime.KieSessionConfiguration;
import org.kie.api.runtime.conf.ClockTypeOption;
import org.kie.api.runtime.rule.ConsequenceException;
import org.kie.api.runtime.rule.EntryPoint;
import org.kie.api.runtime.rule.FactHandle;

/**
 * Fires one compiled rule set: facts in as one JSON string, the result out as one JSON string.
 *
 * Why one call: crossing the JPype boundary per field costs ~25 us a fact; one string each way keeps
 * a 5-fact request well under a millisecond. Each {@link #fire} uses its own session, so a Runner is
 * safe to share between threads; the KieBase is immutable once built.
 */
public final class Runner {
    private final KieBase kieBase;
    /**
     * The network {@link #fire} uses: {@link #kieBase}, or the same rules built to read the joined
     * facts from the request ({@link RequestFacts}; see {@link #Runner(KieBase, KieBase)}).
     */
    private final KieBase fireBase;
    /** How one-shot fires of {@code fireBase} dispatch root {@code in} tests by value (null: none; {@link RequestDispatch}). */
    private final RequestDispatch dispatch;
    /** The order the rule base links its eager (auto-focus) rules in, which one-shot fires of {@code fireBase} keep (null: none; {@link DroolsLinkOrder}). */
    private final DroolsLinkOrder linkOrder;
    private final TypeRegistry types;
    private final boolean hasActionsGlobal;
    private final KieSessionConfiguration sessionConf;
    /**
     * Sessions of {@link #fire} emptied for the next request (null when the rule base does not
     * allow it, see {@link #reusable}). Why: a fresh session creates the memory of every node a
     * request reaches; at 10,000 rules that is ~60% of a 5-fact request. A session whose facts are
     * deleted again keeps those memories, empty, and is back in the state of a fresh one.
     */
    private final java.util.concurrent.ConcurrentLinkedQueue<KieSession> idle;
    /**
     * Whether a rule uses date-effective or date-expires. Drools compares those with the session
     * clock; KIE's sessions run on a realtime clock, so a rule effective "since 2020" fires there.
     * The gateway's pseudo clocks start at 0 (1970) for reproducible replays: for such a rule base
     * they start at the wall-clock time instead (see {@link #startClock}), or those rules would
     * never (or always) fire.
     */
    private final boolean calendarRules;
    /**
     * Whether {@link #giveBack} fires an emptied session before offering it again: only a rule base
     * with agenda groups or auto-focus needs it (see there); for the others that fire is a cost of
     * every request (about 3% of a 5-fact fire of the reception set) that changes nothing.
     */
    private final boolean settleDeletions;
    static final int IDLE_SESSIONS = 8;
    static final int REUSE_MAX_FACTS = 1000;

    public Runner(KieBase kieBase) {
        this(kieBase, null);
    }

    /**
     * A runner whose one-shot {@link #fire} uses {@code requestJoins}, the same rules built by
     * {@link PlainRules#build} to read the facts of every pattern after a rule's first from the
     * request, when {@link #requestJoinsAllowed} (null: {@code kieBase} for everything). Stateful
     * sessions, KIE batches and explain use {@code kieBase}: their facts change between fires.
     */
    public Runner(KieBase kieBase, KieBase requestJoins) {
        this.kieBase = kieBase;
        this.types = new TypeRegistry(kieBase);
        this.hasActionsGlobal = declaresGlobal(kieBase, "actions");
        this.sessionConf = KieServices.Factory.get().newKieSessionConfiguration();
        this.sessionConf.setOption(ClockTypeOption.get("pseudo"));
        this.idle = reusable(kieBase, types) ? new java.util.concurrent.ConcurrentLinkedQueue<KieSession>() : null;
        this.calendarRules = usesCalendarAttributes(kieBase);
        DroolsLinkOrder order = null;
        boolean usable = requestJoins != null && requestJoinsAllowed(types);
        if (usable) {
            try {
                order = DroolsLinkOrder.of(kieBase);  // null: no eager rule, so none with auto-focus
                usable = order == null || order.sameFocusOrder(requestJoins);  // else the groups could take the focus otherwise
            } catch (IllegalStateException e) {  // the link order is not known: not exact
                usable = false;
            }
        }
        this.fireBase = usable ? requestJoins : kieBase;
        this.dispatch = usable ? RequestDispatch.of(fireBase) : null;
        this.linkOrder = usable ? order : null;
        this.settleDeletions = movesFocus(kieBase);
    }

    /**
     * Whether a request-join network answers as the rule base itself: its rules are plain (their
     * then-parts only call globals, so no fact changes while a request fires; the caller builds it
     * only then), and no type is an event (an event's expiry and the clock belong to the session's
     * memory, not to one request).
     */
    static boolean requestJoinsAllowed(TypeRegistry types) {
        return !types.hasEventTypes();
    }

    /**
     * How many memories a fact must enter on insert, in a type's node without an alpha test, before
     * {@link #requestJoinsPay} says a request-join network is worth its cost (a second network in
     * memory, a second build). Measured (docs/benchmarks.md, issue 30): at 10,000 business rules
     * (3,498 accumulates straight under the loan type) a fire takes a third of the time; at 1,000
     * (316) the two are level; on the first growth generator's sets (every joined pattern has a test
     * of its own) the rule base is faster.
     */
    public static final int REQUEST_JOINS_FAN_OUT = 1000;

    /** Whether {@code auto} builds a request-join network for {@code kb}: its facts fan out widely
     *  enough. It answers exactly as {@code kb} does, auto-focus rules included ({@link DroolsLinkOrder};
     *  {@code tests/engine/test_request_joins.py} compares whole answers). */
    public static boolean requestJoinsPay(KieBase kb) {
        return DroolsInternals.untestedRightInputs(kb) >= REQUEST_JOINS_FAN_OUT;
    }

    /** Whether {@link #fire} reads joined facts from the request (a request-join network is in use). */
    public boolean readsJoinsFromRequest() { return fireBase != kieBase; }

    /** How many first patterns {@link #fire} dispatches by value ({@link RequestDispatch}; 0: none). */
    public int routedPatterns() { return dispatch == null ? 0 : dispatch.patterns(); }

    static boolean movesFocus(KieBase kb) {
        for (KiePackage p : kb.getKiePackages()) {
            for (org.kie.api.definition.rule.Rule r : p.getRules()) {
                if (DroolsInternals.movesFocus(r)) return true;
            }
        }
        return false;
    }

    /** Whether {@link #giveBack} fires an emptied session to settle its deletions (see {@link #settleDeletions}). */
    public boolean settlesDeletions() { return settleDeletions; }

    static boolean usesCalendarAttributes(KieBase kb) {
        for (KiePackage p : kb.getKiePackages()) {
            for (org.kie.api.definition.rule.Rule r : p.getRules()) {
                if (DroolsInternals.hasCalendarAttributes(r)) return true;
            }
        }
        return false;
    }

    /** Moves a pseudo clock to the wall-clock time (never back) when the rule base has calendar rules. */
    private KieSession startClock(KieSession s) {
        if (calendarRules && s.getSessionClock() instanceof org.kie.api.time.SessionPseudoClock) {
            long behind = System.currentTimeMillis() - s.getSessionClock().getCurrentTime();
            if (behind > 0) {
                ((org.kie.api.time.SessionPseudoClock) s.getSessionClock()).advanceTime(behind, java.util.concurrent.TimeUnit.MILLISECONDS);
            }
        }
        return s;
    }

    /**
     * Whether a session emptied by deleting its facts answers exactly as a fresh one: every rule
     * needs a fact to match (it starts with a plain pattern, so nothing of it survives the delete
     * and nothing can be left "already fired"), has no timer or rule-flow group, and no declared
     * type is an event (expiry and the clock belong to one session's life). Agenda groups and
     * auto-focus are fine once {@link #giveBack} has let the deletions reach the agenda.
     */
    static boolean reusable(KieBase kb, TypeRegistry types) {
        if (types.hasEventTypes()) return false;
        for (KiePackage p : kb.getKiePackages()) {
            for (org.kie.api.definition.rule.Rule r : p.getRules()) {
                if (!DroolsInternals.matchesOnlyFromFacts(r)) return false;
            }
        }
        return true;
    }

    /** Whether {@link #fire} reuses emptied sessions for this rule base (see {@link #reusable}). */
    public boolean reusesSessions() { return idle != null; }

    KieSession takeSession() {
        KieSession s = idle == null ? null : idle.poll();
        return startClock(s != null ? s : fireBase.newKieSession(sessionConf, null));
    }

    /**
     * Deletes what a request left (its facts, and what its rules inserted) and keeps the session
     * for the next request; disposes it when it holds too much to be worth emptying.
     *
     * Why the fire after the deletes: Drools queues a delete (its propagation list) until the next
     * {@code fireAllRules}. Left queued, the next request's fire would propagate the old facts'
     * deletions and the new facts' insertions in one pass: the rules the deletions unlink are
     * requeued in their agenda groups while the insertions link rules again, and the auto-focus
     * rules (evaluated eagerly, each pushing its group onto the focus stack when it matches) were
     * then evaluated in another order than in a fresh session: the groups fired in another order
     * (25 of 80 requests of a 300-rule business set). Fired here, on a session without facts, the
     * deletions settle before the next request: nothing can fire (every rule needs a fact, see
     * {@link #reusable}) and the focus is back on MAIN; a session where either is not so is dropped.
     * A rule base without agenda groups or auto-focus skips that fire (as before agenda groups were
     * allowed here): with one agenda group, the deletions reaching it with the next insertions
     * change no order (tests/engine/test_incremental.py's reuse tests compare with fresh sessions).
     */
    void giveBack(KieSession session) {
        try {
            int facts = 0;
            for (EntryPoint ep : session.getEntryPoints()) facts += ep.getFactCount();
            if (facts <= REUSE_MAX_FACTS && idle.size() < IDLE_SESSIONS) {
                for (EntryPoint ep : session.getEntryPoints()) {
                    for (FactHandle h : new ArrayList<FactHandle>(ep.getFactHandles())) ep.delete(h);
                }
                boolean settled = !settleDeletions
                        || (session.fireAllRules() == 0 && "MAIN".equals(DroolsInternals.focusName(session)));
                if (settled && session.getFactCount() == 0) {
                    idle.offer(session);
                    return;
                }
            }
        } catch (RuntimeException e) {
            // fall through: a session that cannot be emptied is not reused
        }
        session.dispose();
    }

    static boolean declaresGlobal(KieBase kb, String name) {
        for (KiePackage p : kb.getKiePackages()) {
            for (Global g : p.getGlobalVariables()) if (g.getName().equals(name)) return true;
        }
        return false;
    }

    public TypeRegistry types() { return types; }

    public String describeTypes() { return types.describe(); }

    public String typeFullNames() { return types.fullNames(); }

    public int ruleCount() {
        return ruleNames().length;
    }

    /** The names of the rule base's rules; not its queries, which Drools lists among a package's rules. */
    public String[] ruleNames() {
        List<String> names = new ArrayList<String>();
        for (KiePackage p : kieBase.getKiePackages()) {
            java.util.Set<String> queries = new java.util.HashSet<String>();
            for (org.kie.api.definition.rule.Query q : p.getQueries()) queries.add(q.getName());
            for (org.kie.api.definition.rule.Rule r : p.getRules()) {
                if (!queries.contains(r.getName())) names.add(r.getName());
            }
        }
        return names.toArray(new String[0]);
    }

    KieSession newSession() {
        return startClock(kieBase.newKieSession(sessionConf, null));
    }

    /** A session with a realtime clock (KIE's default) or, as {@link #newSession()}, a pseudo clock. */
    KieSession newSession(boolean realtime) {
        if (!realtime) return newSession();
        KieSessionConfiguration conf = KieServices.Factory.get().newKieSessionConfiguration();
        conf.setOption(ClockTypeOption.get("realtime"));
        return kieBase.newKieSession(conf, null);
    }

    /** Fires {@code factsJson} (a JSON list of facts) in a fresh session, with no time limit. */
    public String fire(String factsJson, int limit, boolean returnFacts, boolean recordFacts) {
        return fire(factsJson, limit, returnFacts, recordFacts, 0L);
    }

    /** Fires {@code factsJson} in a fresh session; a fire running longer than {@code timeoutMs}
     *  (0: no limit) is halted and answers {@code {"ok":false,"kind":"timeout"}} (see {@link Watchdog}). */
    public String fire(String factsJson, int limit, boolean returnFacts, boolean recordFacts, long timeoutMs) {
        List<Object> facts = new ArrayList<Object>();
        String error = buildFacts(types, factsJson, facts);
        if (error != null) return error;
        KieSession session = takeSession();
        boolean reuse = false;
        try {
            Actions actions = new Actions();
            if (hasActionsGlobal) session.setGlobal("actions", actions);
            boolean request = readsJoinsFromRequest();
            Recorder recorder = new Recorder(actions, types, recordFacts, request);
            session.addEventListener(recorder);
            if (request) RequestFacts.open(facts);
            String answer;
            try {
                insert(session, facts, request);
                answer = fireAndReport(session, recorder, types, limit, returnFacts, null, timeoutMs);
            } finally {
                if (request) RequestFacts.close();
            }
            session.removeEventListener(recorder);
            reuse = idle != null && answer.startsWith("{\"ok\":true");  // not after a loop or a failing then-part
            return answer;
        } finally {
            if (reuse) giveBack(session);
            else session.dispose();
        }
    }

    /**
     * Inserts a request's facts in order; into the request-join network, each followed by its
     * {@link RequestDispatch} facts and, where the rule base has eager rules, propagated at once so
     * that the rules it links are evaluated in the rule base's order ({@link DroolsLinkOrder}).
     */
    private void insert(KieSession session, List<Object> facts, boolean request) {
        EntryPoint routes = request && dispatch != null ? dispatch.routes(session) : null;
        DroolsLinkOrder.Fire order = request && linkOrder != null ? linkOrder.begin(session) : null;
        for (Object f : facts) {
            FactHandle h = session.insert(f);
            if (routes != null) dispatch.route(routes, f);
            if (order != null) order.inserted(h);
        }
    }

    /** Fires the session with the runaway guard and writes the result (shared with stateful sessions). */
    static String fireAndReport(KieSession session, Recorder recorder, TypeRegistry types, int limit, boolean returnFacts) {
        return fireAndReport(session, recorder, types, limit, returnFacts, null);
    }

    /** {@link #fireAndReport} through an agenda filter (null: none). */
    static String fireAndReport(KieSession session, Recorder recorder, TypeRegistry types, int limit, boolean returnFacts,
                                org.kie.api.runtime.rule.AgendaFilter filter) {
        return fireAndReport(session, recorder, types, limit, returnFacts, filter, 0L);
    }

    /** {@link #fireAndReport} through an agenda filter (null: none), halted after {@code timeoutMs} (0: never). */
    static String fireAndReport(KieSession session, Recorder recorder, TypeRegistry types, int limit, boolean returnFacts,
                                org.kie.api.runtime.rule.AgendaFilter filter, long timeoutMs) {
        int n;
        Watchdog.Watch watch = Watchdog.watch(session, timeoutMs);
        try {
            n = filter == null ? session.fireAllRules(limit) : session.fireAllRules(filter, limit);
            if (watch != null && watch.halted) {
                recorder.reset();
                return timeoutError(timeoutMs, n);
            }
            if (n >= limit && (filter == null ? session.fireAllRules(1) : session.fireAllRules(filter, 1)) > 0) return recorder.runaway(limit);
        } catch (ConsequenceException ce) {
            recorder.reset();
            return runtimeError(ce.getMatch() == null ? null : ce.getMatch().getRule().getName(), rootMessage(ce));
        } catch (RuntimeException re) {
            recorder.reset();
            return runtimeError(null, rootMessage(re));
        } finally {
            Watchdog.release(watch);
        }
        StringBuilder b = new StringBuilder(256);
        recorder.writeSuccess(b, n);
        if (returnFacts) {
            b.append(",\"facts\":");
            writeObjects(b, inInsertionOrder(session), types);
        }
        b.append('}');
        return b.toString();
    }

    /** The session's facts in the order they were inserted (a session's own store iterates in hash
     *  order, which would differ between a fresh and a reused session). */
    static List<Object> inInsertionOrder(KieSession session) {
        List<FactHandle> handles = new ArrayList<FactHandle>(session.getFactHandles());
        handles.sort((x, y) -> Long.compare(DroolsInternals.handleId(x), DroolsInternals.handleId(y)));
        List<Object> out = new ArrayList<Object>(handles.size());
        for (FactHandle h : handles) out.add(DroolsInternals.objectOf(h));
        return out;
    }

    static void writeObjects(StringBuilder b, Collection<?> objects, TypeRegistry types) {
        b.append('[');
        boolean first = true;
        for (Object o : objects) {
            if (o instanceof Actions) continue;
            if (!first) b.append(',');
            first = false;
            Json.write(b, o, types);
        }
        b.append(']');
    }

    /** The answer of a fire halted by its time limit, after {@code fired} firings. */
    static String timeoutError(long timeoutMs, int fired) {
        return "{\"ok\":false,\"kind\":\"timeout\",\"limit_ms\":" + timeoutMs + ",\"fired\":" + fired + "}";
    }

    static String runtimeError(String rule, String message) {
        StringBuilder b = new StringBuilder("{\"ok\":false,\"kind\":\"runtime\",\"rule\":");
        if (rule == null) b.append("null"); else Json.quote(b, rule);
        b.append(",\"message\":");
        Json.quote(b, message == null ? "unknown error" : message);
        b.append('}');
        return b.toString();
    }

    static String rootMessage(Throwable t) {
        Throwable c = t;
        while (c.getCause() != null && c.getCause() != c) c = c.getCause();
        return c.getClass().getSimpleName() + ": " + c.getMessage();
    }

    /**
     * Parses and builds facts; on any problem returns the error JSON (all problems, not just the
     * first) and builds nothing usable.
     */
    static String buildFacts(TypeRegistry types, String json, List<Object> out) {
        Object parsed;
        try {
            parsed = Json.parse(json);
        } catch (Json.ParseException e) {
            return factError(-1, null, null, null, "facts are not valid JSON: " + e.getMessage());
        }
        if (!(parsed instanceof List)) return factError(-1, null, null, null, "facts must be a JSON list of objects");
        List<?> list = (List<?>) parsed;
        StringBuilder errors = null;
        int errorCount = 0;
        for (int k = 0; k < list.size(); k++) {
            Object item = list.get(k);
            String problem = null, typeName = null, field = null, id = null;
            if (!(item instanceof Map)) {
                problem = "a fact must be a JSON object with a \"type\", got " + TypeRegistry.describe(item);
            } else {
                Map<?, ?> m = (Map<?, ?>) item;
                Object t = m.get("type");
                Object idv = m.get("id");
                id = idv == null ? null : String.valueOf(idv);
                if (!(t instanceof String)) {
                    problem = "a fact needs a \"type\" naming a declared type (one of: " + types.knownTypes() + ")";
                    field = "type";
                } else {
                    typeName = (String) t;
                    TypeRegistry.TypeInfo info = types.type(typeName);
                    if (info == null) {
                        problem = "unknown type '" + typeName + "' (declared types: " + types.knownTypes() + ")";
                        field = "type";
                    } else {
                        try {
                            out.add(types.build(info, m, 0));
                        } catch (TypeRegistry.FactProblem p) {
                            problem = p.getMessage();
                            field = p.field;
                        }
                    }
                }
            }
            if (problem != null) {
                if (errorCount < 100) {
                    errors = errors == null ? new StringBuilder() : errors.append(',');
                    appendError(errors, k, typeName, field, id, problem);
                }
                errorCount++;
            }
        }
        if (errors == null) return null;
        return "{\"ok\":false,\"kind\":\"facts\",\"errorCount\":" + errorCount + ",\"errors\":[" + errors + "]}";
    }

    static String factError(int index, String type, String field, String id, String message) {
        StringBuilder b = new StringBuilder("{\"ok\":false,\"kind\":\"facts\",\"errorCount\":1,\"errors\":[");
        appendError(b, index, type, field, id, message);
        return b.append("]}").toString();
    }

    private static void appendError(StringBuilder b, int index, String type, String field, String id, String message) {
        b.append("{\"index\":").append(index).append(",\"type\":");
        if (type == null) b.append("null"); else Json.quote(b, type);
        b.append(",\"id\":");
        if (id == null) b.append("null"); else Json.quote(b, id);
        b.append(",\"field\":");
        if (field == null) b.append("null"); else Json.quote(b, field);
        b.append(",\"message\":");
        Json.quote(b, message);
        b.append('}');
    }
}
