package org.printeps.gateway;

import java.util.ArrayList;
import java.util.Collections;
import java.util.HashMap;
import java.util.HashSet;
import java.util.IdentityHashMap;
import java.util.LinkedHashMap;
import java.util.List;
import java.util.Map;
import java.util.Set;
import java.util.concurrent.TimeUnit;
import java.util.function.Function;

import org.kie.api.runtime.KieSession;
import org.kie.api.runtime.rule.AgendaFilter;
import org.kie.api.runtime.rule.EntryPoint;
import org.kie.api.runtime.rule.FactHandle;
import org.kie.api.time.SessionClock;
import org.kie.api.time.SessionPseudoClock;

/**
 * Carrying a session's state into a fresh {@link Session}: a move to a new rule set version
 * ({@link #move}, as {@code KieContainer.updateToVersion} does for a live session) and a durable
 * session's snapshot and restore ({@link #snapshot}, {@link #restoreFacts}, {@link #refract},
 * {@link #takePending}). Both check everything first (a state that does not fit changes nothing),
 * then insert the facts in their order into their entry points, set the clock, globals and the
 * agenda-group focus stack, keep the fact handles clients hold as aliases, and carry refraction (see {@link Refraction}):
 * the matches that had fired do not fire again, the pending ones do.
 */
final class Carry {
    private Carry() {}

    /** A state checked against the target session's version, ready to go in. */
    static final class Plan {
        final List<Object> built = new ArrayList<Object>();
        final List<EntryPoint> targets = new ArrayList<EntryPoint>();
        final Map<String, Object> globals = new LinkedHashMap<String, Object>();
        long now;
        /** The agenda-group focus stack, bottom (MAIN) to top (the focus); see {@link DroolsInternals#focusStack}. */
        List<String> stack = Collections.singletonList("MAIN");
        /** The snapshot's {@code applied} stack ("name", "name*" when active; see {@link DroolsInternals#appliedFocusStack}), or null (an older snapshot). */
        List<String> applied;
        /** The handle texts clients hold per fact (restore), in the order of {@link #built}. */
        final List<Object> keys = new ArrayList<Object>();
        /** The snapshot's pending matches (a list of keys), or null: every match had fired. */
        Object pending;
        final Set<Object> restored = Collections.newSetFromMap(new IdentityHashMap<Object, Boolean>());
        /** The handle each fact went in with -> its place in {@link #built} (identity): what {@link Refraction} keys carried matches by. */
        final Map<FactHandle, Integer> handles = new IdentityHashMap<FactHandle, Integer>();
    }

    static String problem(String message) {
        StringBuilder b = new StringBuilder("{\"ok\":false,\"message\":");
        Json.quote(b, message);
        return b.append('}').toString();
    }

    /**
     * Builds one fact (its JSON values) as the target's type, for the entry point {@code ep};
     * a problem message naming {@code what} (and {@code version}: "the version", "the new
     * version"), or null.
     */
    private static String plan(Session into, Plan plan, Map<?, ?> values, String ep, String what, String version) {
        TypeRegistry mine = into.runner.types();
        String type = String.valueOf(values.get("type"));
        TypeRegistry.TypeInfo info = mine.type(type);
        if (info == null) return what + ": " + version + " declares no type " + type;
        try {
            plan.built.add(mine.build(info, values, 0));
        } catch (TypeRegistry.FactProblem p) {
            return what + " (" + type + ") does not fit " + version + ": " + p.getMessage();
        }
        EntryPoint target = into.session.getEntryPoint(ep);
        if (target == null) return what + ": " + version + " has no entry point " + ep;
        plan.targets.add(target);
        return null;
    }

    /** The target's declared globals (but {@code actions}) whose {@code saved} value is not null, converted; a problem, or null. */
    private static String planGlobals(Session into, Plan plan, Function<String, Object> saved, String version) {
        TypeRegistry mine = into.runner.types();
        for (org.kie.api.definition.KiePackage p : into.session.getKieBase().getKiePackages()) {
            for (org.kie.api.definition.rule.Global g : p.getGlobalVariables()) {
                if (g.getName().equals("actions")) continue;
                Object value = saved.apply(g.getName());
                if (value == null) continue;
                try {
                    Class<?> type = mine.declaredClass(g.getType());
                    if (type == null) type = Class.forName(g.getType(), false, Carry.class.getClassLoader());
                    plan.globals.put(g.getName(), mine.convertValue(g.getName(), type, value));
                } catch (Exception e) {
                    return "global '" + g.getName() + "' does not fit " + version + ": " + Runner.rootMessage(e);
                }
            }
        }
        return null;
    }

    /** Sets the plan's clock (a pseudo one) and globals in {@code into}: nothing refuses from here on. */
    private static void applyClockAndGlobals(Session into, Plan plan) {
        if (into.clock instanceof SessionPseudoClock) into.advanceTo(plan.now);
        for (Map.Entry<String, Object> g : plan.globals.entrySet()) into.session.setGlobal(g.getKey(), g.getValue());
    }

    /**
     * Pushes the groups of {@code stack} (bottom to top) onto {@code ks}'s focus stack, which holds
     * only {@code MAIN} (its bottom, skipped): the groups below the top then fire, in order, once
     * the ones above are done, as in the session the stack was read from.
     */
    private static void setFocusStack(KieSession ks, List<String> stack) {
        for (int k = 0; k < stack.size(); k++) {
            String group = stack.get(k);
            if (k == 0 && "MAIN".equals(group)) continue;
            ks.getAgenda().getAgendaGroup(group).setFocus();
        }
    }

    /**
     * A snapshot's {@code applied} stack if it is the start of its whole {@code stack} (queued
     * pushes only add on top), else null: the groups' active state then is not restored.
     */
    private static List<String> savedApplied(Map<?, ?> snap, List<String> stack) {
        if (!(snap.get("applied") instanceof List)) return null;
        List<String> out = new ArrayList<String>();
        for (Object group : (List<?>) snap.get("applied")) out.add(String.valueOf(group));
        if (out.isEmpty() || out.size() > stack.size()) return null;
        for (int k = 0; k < out.size(); k++) if (!stack.get(k).equals(bare(out.get(k)))) return null;
        return out;
    }

    private static String bare(String group) { return group.endsWith("*") ? group.substring(0, group.length() - 1) : group; }

    /** The groups a snapshot's {@code applied} stack marks active (none for an older snapshot). */
    private static Set<String> activeGroups(Plan plan) {
        Set<String> out = new HashSet<String>();
        if (plan.applied != null) for (String group : plan.applied) if (group.endsWith("*")) out.add(bare(group));
        return out;
    }

    /**
     * A snapshot's focus stack: its {@code stack} list (bottom to top), or, in a snapshot written
     * before the stack was kept, {@code MAIN} under its {@code focus} (only the top was kept then).
     */
    private static List<String> savedStack(Map<?, ?> snap) {
        List<String> out = new ArrayList<String>();
        if (snap.get("stack") instanceof List && !((List<?>) snap.get("stack")).isEmpty()) {
            for (Object group : (List<?>) snap.get("stack")) out.add(String.valueOf(group));
            return out;
        }
        out.add("MAIN");
        Object focus = snap.get("focus");
        if (focus != null && !"MAIN".equals(String.valueOf(focus))) out.add(String.valueOf(focus));
        return out;
    }

    /**
     * Walks every match on {@code ks}'s agenda, in every agenda group its rules name, without
     * firing any (each is handed to {@code seen} and rejected). Walking consumes the matches.
     */
    private static void walkAll(KieSession ks, java.util.function.Consumer<org.kie.api.runtime.rule.Match> seen) {
        AgendaFilter reject = match -> {
            seen.accept(match);
            return false;
        };
        for (String group : DroolsInternals.agendaGroups(ks.getKieBase())) {
            ks.getAgenda().getAgendaGroup(group).setFocus();
            ks.fireAllRules(reject);
        }
        ks.fireAllRules(reject);
    }

    /**
     * The keys of the matches of {@code rules} that the plan's facts make before anything fires,
     * in every agenda group: found in a throwaway session of {@code into}'s version (same facts,
     * entry points, clock, globals), whose agenda is walked. The target's own agenda must not be
     * walked: walking consumes the matches. A probe that fails refracts nothing: every match fires
     * again rather than one being lost.
     */
    private static Map<String, Integer> probe(Session into, Plan plan, Set<String> rules, Set<Object> facts,
                                              Map<Object, Integer> places) {
        final Map<String, Integer> keys = Refraction.emptyKeys();
        if (rules.isEmpty() || plan.built.isEmpty()) return keys;
        KieSession probe = into.runner.newSession(false);
        try {
            if (Runner.declaresGlobal(probe.getKieBase(), "actions")) probe.setGlobal("actions", new Actions());
            for (Map.Entry<String, Object> g : plan.globals.entrySet()) probe.setGlobal(g.getKey(), g.getValue());
            SessionClock probeClock = probe.getSessionClock();
            if (probeClock instanceof SessionPseudoClock && plan.now > probeClock.getCurrentTime()) {
                ((SessionPseudoClock) probeClock).advanceTime(plan.now - probeClock.getCurrentTime(), TimeUnit.MILLISECONDS);
            }
            for (int k = 0; k < plan.built.size(); k++) {
                if (plan.built.get(k) != null) probe.getEntryPoint(plan.targets.get(k).getEntryPointId()).insert(plan.built.get(k));
            }
            walkAll(probe, match -> {
                String rule = match.getRule().getName();
                if (rules.contains(rule)) Refraction.add(keys, Refraction.key(rule, match.getObjects(), null, facts, places));
            });
        } catch (RuntimeException e) {
            keys.clear();
        } finally {
            probe.dispose();
        }
        return keys;
    }

    private static Set<String> ruleNames(KieSession ks) {
        Set<String> rules = new HashSet<String>();
        for (org.kie.api.definition.KiePackage p : ks.getKieBase().getKiePackages()) {
            for (org.kie.api.definition.rule.Rule r : p.getRules()) rules.add(r.getName());
        }
        return rules;
    }

    // ------------------------------------------------------------------ a move to a new version

    /** See {@link Session#moveFrom}: {@code into} is fresh; both sessions are locked by the caller. */
    static String move(Session into, Session old, String unchangedRulesJson) {
        if (old.disposed) return problem("the session to move is disposed");
        TypeRegistry theirs = old.runner.types();
        List<FactHandle> oldHandles = Handles.all(old.session);
        Plan plan = new Plan();
        for (FactHandle h : oldHandles) {
            Object fact = DroolsInternals.objectOf(h);
            if (fact instanceof Actions) { plan.built.add(null); plan.targets.add(null); continue; }
            StringBuilder json = new StringBuilder();
            if (!theirs.writeFact(json, fact)) {
                return problem("fact " + Handles.external(h) + " is not of a declared type (" + fact.getClass().getName() + ")");
            }
            String error = plan(into, plan, (Map<?, ?>) Json.parse(json.toString()), DroolsInternals.entryPointName(h),
                    "fact " + Handles.external(h), "the new version");
            if (error != null) return problem(error);
        }
        String error = planGlobals(into, plan, name -> {
            Object v = old.session.getGlobals().get(name);
            if (v == null) return null;
            StringBuilder json = new StringBuilder();
            Json.write(json, v, theirs);
            return Json.parse(json.toString());
        }, "the new version");
        if (error != null) return problem(error);
        plan.now = old.clock.getCurrentTime();
        try {
            plan.stack = DroolsInternals.focusStack(old.session);
        } catch (RuntimeException e) {
            return problem("the agenda's focus stack cannot be read: " + Runner.rootMessage(e));
        }
        // the state fits: from here on nothing can refuse
        applyClockAndGlobals(into, plan);
        Map<Object, Object> mapped = new IdentityHashMap<Object, Object>();
        Map<String, FactHandle> oldAliases = old.handles == null ? new HashMap<String, FactHandle>() : old.handles.aliasHandles();
        Map<FactHandle, FactHandle> moved = new IdentityHashMap<FactHandle, FactHandle>();
        int count = 0;
        for (int k = 0; k < oldHandles.size(); k++) {
            Object fact = plan.built.get(k);
            if (fact == null) continue;
            FactHandle nh = plan.targets.get(k).insert(fact);
            plan.handles.put(nh, k);
            FactHandle oh = oldHandles.get(k);
            moved.put(oh, nh);
            mapped.put(DroolsInternals.objectOf(oh), fact);
            plan.restored.add(fact);
            String id = theirs.idOf(DroolsInternals.objectOf(oh));
            if (id != null && !into.runner.types().isEvent(fact)) into.byId.put(id, nh);
            if (into.handles != null) into.handles.alias(DroolsInternals.handleId(oh), DroolsInternals.identityHashCode(oh), nh);
            count++;
        }
        if (into.handles != null) {
            for (Map.Entry<String, FactHandle> a : oldAliases.entrySet()) {
                FactHandle nh = moved.get(a.getValue());
                if (nh == null) continue;
                String[] idHash = a.getKey().split(":");
                into.handles.alias(Long.parseLong(idHash[0]), Integer.parseInt(idHash[1]), nh);
            }
        }
        Map<Object, Integer> places = Refraction.places(plan.built);
        // the old session's pending matches, in every group (consumed: it is discarded after the move);
        // a match the old session's own refraction (from a restore or an earlier move) drops had fired
        final Map<String, Integer> pending = Refraction.emptyKeys();
        Refraction own = old.refraction;
        try {
            walkAll(old.session, match -> {
                if (own == null || own.accept(match)) {
                    Refraction.add(pending, Refraction.key(match.getRule().getName(), match.getObjects(), mapped, plan.restored, places));
                }
            });
        } catch (RuntimeException e) {
            // an agenda that cannot even be walked: its matches count as pending (they fire here)
        }
        old.recorder.reset();
        Set<String> unchangedRules = new HashSet<String>();
        Object parsed = Json.parse(unchangedRulesJson);
        if (parsed instanceof List) for (Object r : (List<?>) parsed) unchangedRules.add(String.valueOf(r));
        // what had fired: the new version's first agenda over the facts that came across, minus the pending
        Map<String, Integer> fired = probe(into, plan, unchangedRules, plan.restored, places);
        Refraction.subtract(fired, pending);
        into.refraction = new Refraction(unchangedRules, fired, places, plan.handles, DroolsInternals.propagationMark(into.session))
                .attach(into.session);
        setFocusStack(into.session, plan.stack);
        return "{\"ok\":true,\"facts\":" + count + "}";
    }

    // ------------------------------------------------------------------ durable sessions

    /** The facts a snapshot writes, in order: every handle of the session but the gateway's {@code actions}. */
    private static List<FactHandle> snapshotHandles(Session s) {
        List<FactHandle> out = new ArrayList<FactHandle>();
        for (FactHandle h : Handles.all(s.session)) if (!(DroolsInternals.objectOf(h) instanceof Actions)) out.add(h);
        return out;
    }

    /** See {@link Session#snapshot}. */
    static String snapshot(Session s) {
        if (s.disposed) return problem("the session is disposed");
        TypeRegistry types = s.runner.types();
        List<String> stack;
        List<String> applied;
        try {
            applied = DroolsInternals.appliedFocusStack(s.session);  // before focusStack runs the queued pushes
            stack = DroolsInternals.focusStack(s.session);  // first: a later walk of the agenda changes it
        } catch (RuntimeException e) {
            return problem("the agenda's focus stack cannot be read: " + Runner.rootMessage(e));
        }
        StringBuilder b = new StringBuilder(4096).append("{\"ok\":true,\"time\":").append(s.clock.getCurrentTime());
        b.append(",\"facts\":[");
        boolean first = true;
        Map<Long, List<String>> all = s.handles != null ? s.handles.allKeys() : null;
        for (FactHandle h : snapshotHandles(s)) {
            Object fact = DroolsInternals.objectOf(h);
            StringBuilder json = new StringBuilder();
            if (!types.writeFact(json, fact)) {
                return problem("fact " + Handles.external(h) + " is not of a declared type (" + fact.getClass().getName() + ")");
            }
            if (!first) b.append(',');
            first = false;
            b.append("{\"ep\":");
            Json.quote(b, DroolsInternals.entryPointName(h));
            b.append(",\"keys\":");
            List<String> keys = all == null ? null : all.get(DroolsInternals.handleId(h));
            if (keys == null) keys = Collections.singletonList(DroolsInternals.handleId(h) + ":" + DroolsInternals.identityHashCode(h));
            Json.write(b, keys, null);
            b.append(",\"fact\":").append(json).append('}');
        }
        b.append("],\"globals\":{");
        first = true;
        for (org.kie.api.definition.KiePackage p : s.session.getKieBase().getKiePackages()) {
            for (org.kie.api.definition.rule.Global g : p.getGlobalVariables()) {
                Object v = g.getName().equals("actions") ? null : s.session.getGlobals().get(g.getName());
                if (v == null) continue;
                if (!first) b.append(',');
                first = false;
                Json.quote(b, g.getName());
                b.append(':');
                Json.write(b, v, types);
            }
        }
        b.append("},\"focus\":");
        Json.quote(b, stack.get(stack.size() - 1));
        b.append(",\"stack\":");
        Json.write(b, stack, null);
        b.append(",\"applied\":");
        Json.write(b, applied, null);
        return b.append('}').toString();
    }

    /**
     * See {@link Session#takePending}: the keys of the matches pending on {@code s}'s agenda, in
     * every agenda group, naming facts by their place in {@link #snapshot}'s list. The walk
     * consumes them: {@code s} is then replaced by a session restored from the snapshot. A match
     * the session's own refraction (from an earlier restore or move) drops had fired: not pending.
     */
    static String takePending(Session s) {
        if (s.disposed) return problem("the session is disposed");
        List<Object> facts = new ArrayList<Object>();
        for (FactHandle h : snapshotHandles(s)) facts.add(DroolsInternals.objectOf(h));
        Map<Object, Integer> places = Refraction.places(facts);
        Set<Object> all = Collections.newSetFromMap(new IdentityHashMap<Object, Boolean>());
        all.addAll(facts);
        List<String> pending = new ArrayList<String>();
        Refraction own = s.refraction;
        walkAll(s.session, match -> {
            if (own == null || own.accept(match)) pending.add(Refraction.key(match.getRule().getName(), match.getObjects(), null, all, places));
        });
        s.recorder.reset();
        StringBuilder b = new StringBuilder();
        Json.write(b, pending, null);
        return b.toString();
    }

    /** See {@link Session#restoreFacts}: checks the snapshot against {@code into}'s version; changes nothing. */
    static Plan restoreFacts(Session into, String snapshotJson, StringBuilder answer) {
        Map<?, ?> snap;
        try {
            snap = (Map<?, ?>) Json.parse(snapshotJson);
        } catch (RuntimeException e) {
            answer.append(problem("the snapshot is not readable JSON: " + Runner.rootMessage(e)));
            return null;
        }
        if (snap == null || !(snap.get("facts") instanceof List) || !(snap.get("time") instanceof Number)) {
            answer.append(problem("the snapshot has no facts list or no time"));
            return null;
        }
        Plan plan = new Plan();
        List<?> facts = (List<?>) snap.get("facts");
        for (int k = 0; k < facts.size(); k++) {
            Object f = facts.get(k);
            if (!(f instanceof Map) || !(((Map<?, ?>) f).get("fact") instanceof Map)) {
                answer.append(problem("snapshot fact " + k + " is not an object with a fact"));
                return null;
            }
            String error = plan(into, plan, (Map<?, ?>) ((Map<?, ?>) f).get("fact"), String.valueOf(((Map<?, ?>) f).get("ep")),
                    "snapshot fact " + k, "the version");
            if (error != null) {
                answer.append(problem(error));
                return null;
            }
            plan.keys.add(((Map<?, ?>) f).get("keys"));
        }
        Map<?, ?> saved = snap.get("globals") instanceof Map ? (Map<?, ?>) snap.get("globals") : new HashMap<String, Object>();
        String error = planGlobals(into, plan, saved::get, "the version");
        if (error != null) {
            answer.append(problem(error));
            return null;
        }
        plan.now = ((Number) snap.get("time")).longValue();
        plan.stack = savedStack(snap);
        plan.applied = savedApplied(snap, plan.stack);
        plan.pending = snap.get("pending");
        answer.append("{\"ok\":true,\"facts\":").append(plan.built.size()).append('}');
        return plan;
    }

    /** Inserts the plan's fact {@code k} into {@code into}, with the handle texts clients hold for it as aliases. */
    private static void insert(Session into, Plan plan, int k) {
        TypeRegistry mine = into.runner.types();
        Object fact = plan.built.get(k);
        FactHandle nh = plan.targets.get(k).insert(fact);
        plan.handles.put(nh, k);
        plan.restored.add(fact);
        String id = mine.idOf(fact);
        if (id != null && !mine.isEvent(fact)) into.byId.put(id, nh);
        if (into.handles == null || !(plan.keys.get(k) instanceof List)) return;
        for (Object key : (List<?>) plan.keys.get(k)) {
            String[] idHash = String.valueOf(key).split(":");
            if (idHash.length != 2) continue;
            try {
                into.handles.alias(Long.parseLong(idHash[0]), Integer.parseInt(idHash[1]), nh);
            } catch (NumberFormatException e) {
                // a key that is no "id:hash" names no handle a client can hold
            }
        }
    }

    private static final java.util.regex.Pattern PLACE = java.util.regex.Pattern.compile("[|\\[,]#(\\d+)");

    /** The places of the facts the pending keys name; null if a key names none (a match over values only). */
    private static Set<Integer> pendingPlaces(List<?> pending) {
        Set<Integer> out = new HashSet<Integer>();
        for (Object key : pending) {
            java.util.regex.Matcher m = PLACE.matcher(String.valueOf(key));
            boolean any = false;
            while (m.find()) {
                out.add(Integer.valueOf(m.group(1)));
                any = true;
            }
            if (!any) return null;
        }
        return out;
    }

    /**
     * See {@link Session#refract}: restores the checked plan (clock, globals, facts, handles, focus stack)
     * so that every match of the restored facts, in every agenda group, counts as fired but the
     * {@code pending} ones (a list of keys; null: none was pending).
     *
     * <p>How: the facts no pending match names go in first (in their order), and the agenda is
     * walked at once, every match dropped: those had all fired (no filter is left for them, so a
     * later modify that their rules do not react to leaves them fired, as in the original). Then
     * the facts the pending matches name go in; of the matches they make, the ones that are not
     * pending are dropped by a filter as they come up (a probe session lists them), unless a
     * propagation after the restore reached them (see {@link Refraction}: a modify their rules do
     * not react to leaves them fired, one they react to fires them again). Why not leave
     * everything to the filter: the restored facts' matches are only evaluated at the next fire, so
     * the first fire after a rebuild evaluated and dropped every one of them (2.8 s for 11,000
     * facts).
     */
    static void refract(Session into, Plan plan, Object pending) {
        List<?> waiting = pending instanceof List ? (List<?>) pending : Collections.emptyList();
        Set<Integer> late = pendingPlaces(waiting);
        applyClockAndGlobals(into, plan);
        boolean walked = late != null;
        for (int k = 0; k < plan.built.size(); k++) if (late == null || !late.contains(k)) insert(into, plan, k);
        if (walked) {
            try {
                walkAll(into.session, match -> { });
            } catch (RuntimeException e) {
                walked = false;  // an agenda that cannot be walked here: the probe and the filter below, for all
            }
        }
        for (int k = 0; late != null && k < plan.built.size(); k++) if (late.contains(k)) insert(into, plan, k);
        into.refraction = null;
        if (!walked || !late.isEmpty()) {
            Set<String> rules = ruleNames(into.session);
            Map<Object, Integer> places = Refraction.places(plan.built);
            Map<String, Integer> fired = probe(into, plan, rules, plan.restored, places);
            if (walked) fired.keySet().removeIf(key -> !namesAny(key, late));  // the others were dropped by the walk
            Map<String, Integer> still = Refraction.emptyKeys();
            for (Object key : waiting) Refraction.add(still, String.valueOf(key));
            Refraction.subtract(fired, still);
            if (!fired.isEmpty()) {
                into.refraction = new Refraction(rules, fired, places, plan.handles, DroolsInternals.propagationMark(into.session))
                        .locking(activeGroups(plan)).attach(into.session);
            }
        }
        setFocusStack(into.session, plan.stack);
        into.recorder.reset();
    }

    private static boolean namesAny(String key, Set<Integer> places) {
        java.util.regex.Matcher m = PLACE.matcher(key);
        while (m.find()) if (places.contains(Integer.valueOf(m.group(1)))) return true;
        return false;
    }
}
