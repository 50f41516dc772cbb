package org.printeps.gateway;

import java.util.ArrayList;
import java.util.Collections;
import java.util.HashSet;
import java.util.IdentityHashMap;
import java.util.List;
import java.util.Map;
import java.util.Set;
import java.util.concurrent.TimeUnit;

import org.kie.api.definition.KiePackage;
import org.kie.api.definition.rule.Global;
import org.kie.api.runtime.KieSession;
import org.kie.api.runtime.rule.EntryPoint;
import org.kie.api.runtime.rule.FactHandle;
import org.kie.api.runtime.rule.QueryResults;
import org.kie.api.runtime.rule.QueryResultsRow;
import org.kie.api.time.SessionPseudoClock;

/**
 * Runs a batch of session commands (the KIE Server batch, already translated to plain commands by
 * the Python side) on one {@link Session}, under its lock.
 *
 * Two phases, so a batch that cannot run changes nothing: first every command is checked against
 * the session as it is (facts built, types and fields checked, fact handles resolved, globals and
 * queries looked up, entry points found); only then are they executed in order. What can only fail
 * while executing (a then-part throwing, the runaway guard, a fact retracted by a rule fired earlier
 * in the same batch) stops the batch at that command, as in KIE Server; the answer names it.
 * Objects in the answer are written after the last command: like KIE Server, a returned object
 * shows its state at the end of the batch.
 *
 * Commands (JSON objects, key "op"): insert {facts, ep, out, ret}, fire {max, out},
 * get_objects {type, ep, out, handles}, get_object {handle, out}, delete {handle},
 * modify {handle, set: [[field, value]...], whole (update without property names, as KIE's ModifyCommand)}, update {handle, fact}, set_global {name, value, out},
 * get_global {name, out}, query {name, args, out}, set_focus {group}, clear_agenda_group {group},
 * clear_agenda, clear_activation_group {group}, advance {ms, out}, get_time {out},
 * get_fact_handles {ep, out}, fact_count {out}, dispose.
 */
final class Batch {
    private final Session s;
    private final KieSession ks;
    private final TypeRegistry types;
    private final int fireLimit;

    /** A command checked in phase one, with what phase two needs. */
    private static final class Prepared {
        final int index;
        final String op;
        final Map<?, ?> cmd;
        final String out;
        List<Object> objects;      // insert: built facts; update: the new fact
        FactHandle handle;         // delete, get_object, modify, update
        List<Object[]> setters;    // modify: [field name, converted value]
        Object value;              // set_global: converted value
        Object[] args;             // query: converted arguments
        EntryPoint entryPoint;
        Prepared(int index, String op, Map<?, ?> cmd) {
            this.index = index;
            this.op = op;
            this.cmd = cmd;
            Object o = cmd.get("out");
            this.out = o == null ? null : String.valueOf(o);
        }
    }

    /** A refusal of the batch: which command and why. */
    static final class Refused extends Exception {
        final int index;
        final String op;
        final String kind;
        final String field;
        Refused(int index, String op, String kind, String field, String message) {
            super(message);
            this.index = index; this.op = op; this.kind = kind; this.field = field;
        }
    }

    Batch(Session s, int fireLimit) {
        this.s = s;
        this.ks = s.session;
        this.types = s.runner.types();
        this.fireLimit = fireLimit;
    }

    // ------------------------------------------------------------------ phase one: check

    String run(String commandsJson) {
        List<?> commands;
        try {
            Object parsed = Json.parse(commandsJson);
            if (!(parsed instanceof List)) throw new Json.ParseException("a list of commands expected", 0);
            commands = (List<?>) parsed;
        } catch (Json.ParseException e) {
            return refusal(new Refused(-1, null, "commands", null, "the commands are not valid JSON: " + e.getMessage()), null);
        }
        List<Prepared> prepared = new ArrayList<Prepared>(commands.size());
        Set<FactHandle> deleted = Collections.newSetFromMap(new IdentityHashMap<FactHandle, Boolean>());
        try {
            for (int k = 0; k < commands.size(); k++) {
                Object c = commands.get(k);
                if (!(c instanceof Map)) throw new Refused(k, null, "commands", null, "a command must be an object");
                Map<?, ?> m = (Map<?, ?>) c;
                Prepared p = new Prepared(k, String.valueOf(m.get("op")), m);
                check(p, deleted);
                prepared.add(p);
            }
        } catch (Refused r) {
            return refusal(r, null);
        }
        return execute(prepared);
    }

    private void check(Prepared p, Set<FactHandle> deleted) throws Refused {
        switch (p.op) {
            case "insert": {
                p.entryPoint = entryPoint(p);
                p.objects = build(p, (List<?>) p.cmd.get("facts"));
                break;
            }
            case "delete":
            case "get_object":
            case "modify":
            case "update": {
                p.handle = handle(p, deleted);
                if (p.op.equals("delete")) deleted.add(p.handle);
                if (p.op.equals("modify")) p.setters = setters(p);
                if (p.op.equals("update")) p.objects = build(p, Collections.singletonList(p.cmd.get("fact")));
                break;
            }
            case "get_objects": p.value = filterClass(p); break;
            case "set_global": p.value = globalValue(p); break;
            case "query": p.args = queryArgs(p); break;
            case "advance":
            case "advance_to":
                if (!(s.clock instanceof SessionPseudoClock)) {
                    throw new Refused(p.index, p.op, "clock", "amount", "the session's clock is realtime: only a pseudo-clock "
                            + "session can be advanced (declare the ksession with clockType=\"pseudo\", or open the session with \"clock\": \"pseudo\")");
                }
                if (number(p, "ms") < 0) throw new Refused(p.index, p.op, "clock", "amount", "the clock cannot be moved back");
                break;
            case "fire": case "get_global": case "set_focus": case "clear_agenda_group":
            case "clear_agenda": case "clear_activation_group": case "get_time": case "get_fact_handles":
            case "fact_count": case "dispose":
                break;
            default:
                throw new Refused(p.index, p.op, "commands", null, "unknown command '" + p.op + "'");
        }
    }

    private EntryPoint entryPoint(Prepared p) throws Refused {
        Object ep = p.cmd.get("ep");
        String name = ep == null || "".equals(ep) ? "DEFAULT" : String.valueOf(ep);
        EntryPoint found = ks.getEntryPoint(name);
        if (found == null) {
            List<String> names = new ArrayList<String>();
            for (EntryPoint e : ks.getEntryPoints()) names.add(e.getEntryPointId());
            Collections.sort(names);
            throw new Refused(p.index, p.op, "facts", "entry-point", "entry point '" + name + "' is not used by the rule set "
                    + "(its entry points: " + String.join(", ", names) + ")");
        }
        return found;
    }

    private List<Object> build(Prepared p, List<?> facts) throws Refused {
        List<Object> out = new ArrayList<Object>(facts == null ? 0 : facts.size());
        if (facts == null) return out;
        for (int k = 0; k < facts.size(); k++) {
            Object item = facts.get(k);
            String where = facts.size() > 1 ? "object " + k + ": " : "";
            if (!(item instanceof Map)) throw new Refused(p.index, p.op, "facts", null, where + "a fact must be an object");
            Map<?, ?> m = (Map<?, ?>) item;
            Object t = m.get("type");
            TypeRegistry.TypeInfo info = t instanceof String ? types.type((String) t) : null;
            if (info == null) {
                throw new Refused(p.index, p.op, "facts", "type", where + "unknown fact class '" + t + "' (the rule set declares: "
                        + types.knownTypes() + ")");
            }
            try {
                out.add(types.build(info, m, 0));
            } catch (TypeRegistry.FactProblem problem) {
                throw new Refused(p.index, p.op, "facts", problem.field, where + info.fullName + ": " + problem.getMessage());
            }
        }
        return out;
    }

    private FactHandle handle(Prepared p, Set<FactHandle> deleted) throws Refused {
        Object text = p.cmd.get("handle");
        FactHandle h;
        try {
            h = s.resolve(text == null ? null : String.valueOf(text));
        } catch (Handles.Stale stale) {
            throw new Refused(p.index, p.op, "handle", "fact-handle", stale.getMessage());
        }
        if (deleted.contains(h)) {
            throw new Refused(p.index, p.op, "handle", "fact-handle", "fact handle " + text + " was retracted by an earlier command of this batch");
        }
        return h;
    }

    /** modify's setters: field names checked against the fact's type; values converted like KIE's (strings are parsed). */
    private List<Object[]> setters(Prepared p) throws Refused {
        Object fact = ks.getObject(p.handle);
        TypeRegistry.TypeInfo info = fact == null ? null : types.type(fact.getClass().getName());
        if (info == null) throw new Refused(p.index, p.op, "handle", "fact-handle", "the fact of handle " + p.cmd.get("handle") + " is not of a declared type");
        List<Object[]> out = new ArrayList<Object[]>();
        Object set = p.cmd.get("set");
        if (!(set instanceof List)) return out;
        for (Object pair : (List<?>) set) {
            List<?> kv = (List<?>) pair;
            String field = String.valueOf(kv.get(0));
            TypeRegistry.FieldInfo f = info.fields.get(field);
            if (f == null) {
                throw new Refused(p.index, p.op, "facts", field, "unknown field '" + field + "' for type " + info.simpleName
                        + " (fields: " + String.join(", ", info.fields.keySet()) + ")");
            }
            if (f.setter == null) throw new Refused(p.index, p.op, "facts", field, "field '" + field + "' cannot be set");
            try {
                out.add(new Object[] {f, types.convertValue(field, f.type, lenient(f.type, kv.get(1)))});
            } catch (TypeRegistry.FactProblem problem) {
                throw new Refused(p.index, p.op, "facts", field, info.simpleName + ": " + problem.getMessage());
            }
        }
        return out;
    }

    /** KIE's modify sends values as text ("value": "30"), MVEL converting them: do the same for simple types. */
    static Object lenient(Class<?> t, Object v) {
        if (!(v instanceof String)) return v;
        String text = ((String) v).trim();
        try {
            if (t == int.class || t == Integer.class || t == long.class || t == Long.class
                    || t == short.class || t == Short.class || t == byte.class || t == Byte.class) return Long.valueOf(text);
            if (t == double.class || t == Double.class || t == float.class || t == Float.class
                    || t == java.math.BigDecimal.class) return Double.valueOf(text);
        } catch (NumberFormatException e) {
            return v;  // the strict conversion reports it
        }
        if (t == boolean.class || t == Boolean.class) {
            if (text.equals("true")) return Boolean.TRUE;
            if (text.equals("false")) return Boolean.FALSE;
        }
        return v;
    }

    /** get_objects' class filter (null: none): a declared type, or a Java class such as
     *  java.lang.Number; an unknown name is refused, as KIE's ClassObjectFilter fails to load it. */
    private Class<?> filterClass(Prepared p) throws Refused {
        Object type = p.cmd.get("type");
        if (type == null) return null;
        String name = String.valueOf(type);
        TypeRegistry.TypeInfo info = types.type(name);
        if (info != null) return info.cls;
        try {
            return Class.forName(name, false, Session.class.getClassLoader());
        } catch (ClassNotFoundException | LinkageError e) {
            throw new Refused(p.index, p.op, "facts", "class-object-filter", "unknown class '" + name
                    + "' in the class-object-filter (the rule set declares: " + types.knownTypes() + ")");
        }
    }

    private Object globalValue(Prepared p) throws Refused {
        String name = String.valueOf(p.cmd.get("name"));
        if ("actions".equals(name)) {
            throw new Refused(p.index, p.op, "globals", "identifier", "the global 'actions' belongs to the gateway and cannot be set");
        }
        String typeName = null;
        for (KiePackage pkg : ks.getKieBase().getKiePackages()) {
            for (Global g : pkg.getGlobalVariables()) if (g.getName().equals(name)) typeName = g.getType();
        }
        if (typeName == null) throw new Refused(p.index, p.op, "globals", "identifier", "the rule set declares no global '" + name + "'");
        try {
            Class<?> type = types.declaredClass(typeName);
            if (type == null) type = Class.forName(typeName, false, Session.class.getClassLoader());
            return types.convertValue(name, type, p.cmd.get("value"));
        } catch (TypeRegistry.FactProblem problem) {
            throw new Refused(p.index, p.op, "globals", "object", "global '" + name + "': " + problem.getMessage());
        } catch (Exception e) {
            throw new Refused(p.index, p.op, "globals", "object", "global '" + name + "': " + Runner.rootMessage(e));
        }
    }

    private Object[] queryArgs(Prepared p) throws Refused {
        String name = String.valueOf(p.cmd.get("name"));
        Class<?>[] declared = s.queryParameterTypes(name);
        if (declared == null) {
            throw new Refused(p.index, p.op, "query", "name", "the rule set has no query '" + name + "'" + s.queryNames());
        }
        Object a = p.cmd.get("args");
        Object[] args = a instanceof List ? ((List<?>) a).toArray() : new Object[0];
        if (args.length != declared.length) {
            throw new Refused(p.index, p.op, "query", "arguments", "query '" + name + "' takes " + declared.length
                    + " argument(s), got " + args.length);
        }
        for (int k = 0; k < args.length; k++) {
            try {
                args[k] = types.convertValue("argument " + k, declared[k], lenient(declared[k], args[k]));
            } catch (TypeRegistry.FactProblem problem) {
                throw new Refused(p.index, p.op, "query", "arguments", "query '" + name + "': " + problem.getMessage());
            }
        }
        return args;
    }

    private static long number(Prepared p, String key) {
        Object v = p.cmd.get(key);
        return v instanceof Number ? ((Number) v).longValue() : 0L;
    }

    // ------------------------------------------------------------------ phase two: execute

    /** What a command produced, written to JSON once the batch is over. */
    private static final class Output {
        final Prepared p;
        Object value;              // an object, a list of objects, a number...
        boolean hasValue;
        List<FactHandle> handles;  // insert: the new handles
        String fire;               // fire: the recorder's JSON
        boolean withHandles;       // get_objects for the REST API: [{handle, fact}]
        List<FactHandle> listed;
        Output(Prepared p) { this.p = p; }
    }

    private String execute(List<Prepared> prepared) {
        List<Output> outputs = new ArrayList<Output>(prepared.size());
        Refused failure = null;
        for (Prepared p : prepared) {
            Output o = new Output(p);
            try {
                if (s.disposed) throw new Refused(p.index, p.op, "disposed", null, "the session was disposed by an earlier command of this batch");
                run(p, o);
            } catch (Refused r) {
                failure = r;
                break;
            } catch (RuntimeException e) {
                failure = new Refused(p.index, p.op, "runtime", null, Runner.rootMessage(e));
                break;
            }
            outputs.add(o);
        }
        StringBuilder b = new StringBuilder(256);
        if (failure != null) return refusal(failure, outputs);
        b.append("{\"ok\":true,\"results\":");
        writeOutputs(b, outputs);
        return finish(b);
    }

    private String finish(StringBuilder b) {
        b.append(",\"disposed\":").append(s.disposed);
        if (!s.disposed) {
            b.append(",\"time\":").append(s.clock.getCurrentTime());
            b.append(",\"factCount\":").append(ks.getFactCount());
        }
        return b.append('}').toString();
    }

    private void run(Prepared p, Output o) throws Refused {
        switch (p.op) {
            case "insert": {
                o.handles = new ArrayList<FactHandle>(p.objects.size());
                for (Object f : p.objects) o.handles.add(p.entryPoint.insert(f));
                if (p.out != null && !Boolean.FALSE.equals(p.cmd.get("ret"))) {
                    o.value = p.objects.size() == 1 && !Boolean.TRUE.equals(p.cmd.get("many")) ? p.objects.get(0) : new ArrayList<Object>(p.objects);
                    o.hasValue = true;
                }
                break;
            }
            case "fire": {
                String result = s.fireForBatch((int) number(p, "max"), fireLimit);
                if (result.startsWith("{\"ok\":false")) throw refusedFire(p, result);
                o.fire = result;
                break;
            }
            case "get_objects": {
                Class<?> type = (Class<?>) p.value;
                List<FactHandle> listed = new ArrayList<FactHandle>();
                List<Object> objects = new ArrayList<Object>();
                for (FactHandle h : handlesIn(p)) {
                    Object f = DroolsInternals.objectOf(h);
                    if (f instanceof Actions) continue;
                    if (type != null && !type.isInstance(f)) continue;
                    listed.add(h);
                    objects.add(f);
                }
                o.withHandles = Boolean.TRUE.equals(p.cmd.get("handles"));
                o.listed = listed;
                o.value = objects;
                o.hasValue = true;
                break;
            }
            case "get_object": o.value = live(p); o.hasValue = true; break;
            case "delete": {
                live(p);
                ks.getEntryPoint(DroolsInternals.entryPointName(p.handle)).delete(p.handle);
                break;
            }
            case "modify": {
                Object fact = live(p);
                String[] names = new String[p.setters.size()];
                int k = 0;
                for (Object[] setter : p.setters) {
                    TypeRegistry.FieldInfo f = (TypeRegistry.FieldInfo) setter[0];
                    try {
                        f.setter.invoke(fact, setter[1]);
                    } catch (Exception e) {
                        throw new Refused(p.index, p.op, "facts", f.name, "cannot set field '" + f.name + "': " + Runner.rootMessage(e));
                    }
                    names[k++] = f.name;
                }
                EntryPoint ep = ks.getEntryPoint(DroolsInternals.entryPointName(p.handle));
                if (Boolean.TRUE.equals(p.cmd.get("whole"))) ep.update(p.handle, fact);  // KIE's ModifyCommand
                else ep.update(p.handle, fact, names);  // only the rules that react to these fields
                o.value = fact;
                o.hasValue = p.out != null;
                break;
            }
            case "update": {
                live(p);
                EntryPoint ep = ks.getEntryPoint(DroolsInternals.entryPointName(p.handle));
                ep.update(p.handle, p.objects.get(0));
                break;
            }
            case "set_global": {
                ks.setGlobal(String.valueOf(p.cmd.get("name")), p.value);
                if (p.out != null) { o.value = p.value; o.hasValue = true; }
                break;
            }
            case "get_global": {
                String name = String.valueOf(p.cmd.get("name"));
                o.value = "actions".equals(name) ? null : ks.getGlobals().get(name);
                o.hasValue = true;
                break;
            }
            case "query": {
                QueryResults results;
                try {
                    results = ks.getQueryResults(String.valueOf(p.cmd.get("name")), p.args);
                } catch (RuntimeException e) {
                    throw new Refused(p.index, p.op, "query", "name", "query '" + p.cmd.get("name") + "' failed: " + Runner.rootMessage(e));
                }
                List<Object> rows = new ArrayList<Object>();
                List<Object> handles = new ArrayList<Object>();
                String[] ids = results.getIdentifiers();
                for (QueryResultsRow row : results) {
                    // as KIE's FlatQueryResults: the identifiers that have a fact handle, with it
                    java.util.LinkedHashMap<String, Object> r = new java.util.LinkedHashMap<String, Object>();
                    java.util.LinkedHashMap<String, Object> hs = new java.util.LinkedHashMap<String, Object>();
                    for (String id : ids) {
                        FactHandle h = row.getFactHandle(id);
                        if (h == null) continue;
                        Object v = row.get(id);
                        r.put(id, v);
                        hs.put(id, DroolsInternals.disconnectedHandle(h, v));
                    }
                    rows.add(r);
                    handles.add(hs);
                }
                java.util.LinkedHashMap<String, Object> value = new java.util.LinkedHashMap<String, Object>();
                value.put("identifiers", java.util.Arrays.asList(ids));
                value.put("rows", rows);
                value.put("handles", handles);
                o.value = value;
                o.hasValue = true;
                break;
            }
            case "set_focus": {
                String group = String.valueOf(p.cmd.get("group"));
                ks.getAgenda().getAgendaGroup(group).setFocus();
                if (s.refraction != null) s.refraction.pushed(group);  // a push deactivates the group under it
                break;
            }
            case "clear_agenda_group": ks.getAgenda().getAgendaGroup(String.valueOf(p.cmd.get("group"))).clear(); break;
            case "clear_agenda": ks.getAgenda().clear(); break;
            case "clear_activation_group": ks.getAgenda().getActivationGroup(String.valueOf(p.cmd.get("group"))).clear(); break;
            case "advance": {
                ((SessionPseudoClock) s.clock).advanceTime(number(p, "ms"), TimeUnit.MILLISECONDS);
                o.value = s.clock.getCurrentTime();
                o.hasValue = true;
                break;
            }
            case "advance_to": {  // to a timestamp; never back (an event older than the clock is simply inserted)
                long to = number(p, "to");
                long now = s.clock.getCurrentTime();
                if (to > now) ((SessionPseudoClock) s.clock).advanceTime(to - now, TimeUnit.MILLISECONDS);
                o.value = s.clock.getCurrentTime();
                o.hasValue = true;
                break;
            }
            case "get_time": o.value = s.clock.getCurrentTime(); o.hasValue = true; break;
            case "fact_count": o.value = ks.getFactCount(); o.hasValue = true; break;
            case "get_fact_handles": {
                List<Object> texts = new ArrayList<Object>();
                for (FactHandle h : handlesIn(p)) {
                    if (!(DroolsInternals.objectOf(h) instanceof Actions)) texts.add(Handles.external(h));
                }
                o.value = texts;
                o.hasValue = true;
                break;
            }
            case "dispose": s.dispose(); break;
            default: throw new Refused(p.index, p.op, "commands", null, "unknown command '" + p.op + "'");
        }
    }

    /** The handles a listing command reads: of its entry point "ep" only (KIE's getObjects() and
     *  getFactHandles() read the default entry point), else of every entry point (the REST API). */
    private List<FactHandle> handlesIn(Prepared p) {
        Object ep = p.cmd.get("ep");
        if (ep == null) return Handles.all(ks);
        List<FactHandle> out = new ArrayList<FactHandle>();
        for (FactHandle h : Handles.all(ks)) {
            if (ep.equals(DroolsInternals.entryPointName(h))) out.add(h);
        }
        return out;
    }

    private Object live(Prepared p) throws Refused {
        Object f = ks.getObject(p.handle);
        if (f == null) {
            throw new Refused(p.index, p.op, "handle", "fact-handle", "fact handle " + p.cmd.get("handle")
                    + " is no longer in the session (a rule fired earlier in this batch retracted it)");
        }
        return f;
    }

    private static Refused refusedFire(Prepared p, String answer) {
        Object parsed = Json.parse(answer);
        Map<?, ?> m = (Map<?, ?>) parsed;
        String kind = String.valueOf(m.get("kind"));
        String message;
        if ("runaway".equals(kind)) {
            message = "rules still firing after " + m.get("limit") + " firings (a rule loop?): " + Json.toJson(m.get("counts"));
        } else if ("timeout".equals(kind)) {
            message = "the fire was stopped after its time limit of " + m.get("limit_ms") + " ms (engine.fire_timeout_s), "
                    + m.get("fired") + " rules had fired";
        } else {
            Object rule = m.get("rule");
            message = (rule == null ? "" : "rule '" + rule + "': ") + m.get("message");
        }
        return new Refused(p.index, p.op, kind, null, message);
    }

    // ------------------------------------------------------------------ the answer

    private void writeOutputs(StringBuilder b, List<Output> outputs) {
        b.append('[');
        boolean first = true;
        for (Output o : outputs) {
            if (!first) b.append(',');
            first = false;
            b.append("{\"i\":").append(o.p.index).append(",\"op\":");
            Json.quote(b, o.p.op);
            if (o.p.out != null) {
                b.append(",\"out\":");
                Json.quote(b, o.p.out);
            }
            if (o.handles != null) {
                b.append(",\"handles\":[");
                for (int k = 0; k < o.handles.size(); k++) {
                    if (k > 0) b.append(',');
                    Json.quote(b, Handles.external(o.handles.get(k)));
                }
                b.append(']');
            }
            if (o.fire != null) b.append(",\"fire\":").append(o.fire);
            if (o.withHandles) {
                b.append(",\"value\":[");
                for (int k = 0; k < o.listed.size(); k++) {
                    if (k > 0) b.append(',');
                    FactHandle h = o.listed.get(k);
                    b.append("{\"handle\":");
                    Json.quote(b, Handles.external(h));
                    b.append(",\"fact\":");
                    Json.write(b, DroolsInternals.objectOf(h), types);
                    b.append('}');
                }
                b.append(']');
            } else if (o.hasValue) {
                b.append(",\"value\":");
                Json.write(b, o.value, types);
            }
            b.append('}');
        }
        b.append(']');
    }

    private String refusal(Refused r, List<Output> done) {
        StringBuilder b = new StringBuilder("{\"ok\":false,\"index\":").append(r.index).append(",\"op\":");
        if (r.op == null) b.append("null"); else Json.quote(b, r.op);
        b.append(",\"kind\":");
        Json.quote(b, r.kind);
        b.append(",\"field\":");
        if (r.field == null) b.append("null"); else Json.quote(b, r.field);
        b.append(",\"message\":");
        Json.quote(b, r.getMessage());
        b.append(",\"applied\":").append(done != null && !done.isEmpty());
        if (done != null) {
            b.append(",\"results\":");
            writeOutputs(b, done);
        }
        return finish(b);
    }
}
