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

/**
 * Fires one compiled rule set: facts in as one JSON string, the result out as one JSON string.
 *
 * Why one call: crossing the JPype boundary per field costs ~25 us a fact; one string each way keeps
 * a 5-fact request well under a millisecond. Each {@link #fire} uses its own session, so a Runner is
 * safe to share between threads; the KieBase is immutable once built.
 */
public final class Runner {
    private final KieBase kieBase;
    private final TypeRegistry types;
    private final boolean hasActionsGlobal;
    private final KieSessionConfiguration sessionConf;

    public Runner(KieBase kieBase) {
        this.kieBase = kieBase;
        this.types = new TypeRegistry(kieBase);
        this.hasActionsGlobal = declaresGlobal(kieBase, "actions");
        this.sessionConf = KieServices.Factory.get().newKieSessionConfiguration();
        this.sessionConf.setOption(ClockTypeOption.get("pseudo"));
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
        int n = 0;
        for (KiePackage p : kieBase.getKiePackages()) n += p.getRules().size();
        return n;
    }

    KieSession newSession() {
        return kieBase.newKieSession(sessionConf, null);
    }

    /** A session with a realtime clock (KIE's default) or, as {@link #newSession()}, a pseudo clock. */
    KieSession newSession(boolean realtime) {
        if (!realtime) return newSession();
        KieSessionConfiguration conf = KieServices.Factory.get().newKieSessionConfiguration();
        conf.setOption(ClockTypeOption.get("realtime"));
        return kieBase.newKieSession(conf, null);
    }

    /** Fires {@code factsJson} (a JSON list of facts) in a fresh session. */
    public String fire(String factsJson, int limit, boolean returnFacts, boolean recordFacts) {
        List<Object> facts = new ArrayList<Object>();
        String error = buildFacts(types, factsJson, facts);
        if (error != null) return error;
        KieSession session = newSession();
        try {
            Actions actions = new Actions();
            if (hasActionsGlobal) session.setGlobal("actions", actions);
            Recorder recorder = new Recorder(actions, types, recordFacts);
            session.addEventListener(recorder);
            for (Object f : facts) session.insert(f);
            return fireAndReport(session, recorder, types, limit, returnFacts);
        } finally {
            session.dispose();
        }
    }

    /** Fires the session with the runaway guard and writes the result (shared with stateful sessions). */
    static String fireAndReport(KieSession session, Recorder recorder, TypeRegistry types, int limit, boolean returnFacts) {
        return fireAndReport(session, recorder, types, limit, returnFacts, null);
    }

    /** {@link #fireAndReport} through an agenda filter (null: none). */
    static String fireAndReport(KieSession session, Recorder recorder, TypeRegistry types, int limit, boolean returnFacts,
                                org.kie.api.runtime.rule.AgendaFilter filter) {
        int n;
        try {
            n = filter == null ? session.fireAllRules(limit) : session.fireAllRules(filter, limit);
            if (n >= limit && (filter == null ? session.fireAllRules(1) : session.fireAllRules(filter, 1)) > 0) return recorder.runaway(limit);
        } catch (ConsequenceException ce) {
            recorder.reset();
            return runtimeError(ce.getMatch() == null ? null : ce.getMatch().getRule().getName(), rootMessage(ce));
        } catch (RuntimeException re) {
            recorder.reset();
            return runtimeError(null, rootMessage(re));
        }
        StringBuilder b = new StringBuilder(256);
        recorder.writeSuccess(b, n);
        if (returnFacts) {
            b.append(",\"facts\":");
            writeObjects(b, session.getObjects(), types);
        }
        b.append('}');
        return b.toString();
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
