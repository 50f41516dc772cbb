package org.printeps.gateway;

import java.util.ArrayList;
import java.util.HashMap;
import java.util.LinkedHashMap;
import java.util.LinkedHashSet;
import java.util.List;
import java.util.Map;
import java.util.concurrent.ConcurrentHashMap;

import org.drools.model.AlphaIndex;
import org.drools.model.DSL;
import org.drools.model.Declaration;
import org.drools.model.Index;
import org.drools.model.PatternDSL;
import org.drools.model.RuleItemBuilder;
import org.drools.model.functions.Function1;
import org.kie.api.KieBase;
import org.kie.api.definition.KiePackage;
import org.kie.api.runtime.KieSession;
import org.kie.api.runtime.rule.EntryPoint;
import org.printeps.gateway.PlainValues.Kind;
import org.printeps.gateway.PlainValues.Property;

/**
 * A request-join network's {@code in} tests dispatched by value: a rule whose first pattern starts
 * with {@code field in ( v1, v2, … )} (not auto-focus) gets, in that network, a first pattern on a
 * {@link Routed} fact of its pattern's key (equal patterns share one), which Drools hashes with the
 * other keys, and then reads the fact itself from it ({@code from}) with all of the pattern's
 * constraints. A one-shot fire ({@link Runner#fire}) inserts, after each fact, one {@link Routed}
 * per key whose list holds the fact's value: a hash lookup here instead of the fact passing every
 * such test.
 *
 * Why: Drools hashes alpha tests only for single equalities. An {@code in} test at the root of a
 * pattern is a node under its type's node, and every fact of the type runs every one of them: at
 * 10,000 business rules ~900 per applicant, ~40% of a request's time with the other root tests
 * (JFR, issue 30). The value table reproduces {@code InOperator} (the field's value {@code equals}
 * one of the literals, which are text or int of the field's kind), and the read pattern still
 * tests the {@code in} itself; each rule's matches arrive in the order of the facts, as at its own
 * left input. Rules with auto-focus keep their pattern: the order in which they are linked picks
 * the agenda group that fires first; so do rules whose first pattern opens another rule or whose
 * first test is an auto-focus rule's (marked {@code firstShared} by shared_patterns.py), so that
 * the nodes they share keep the children, and the order, they have in the rule base.
 */
public final class RequestDispatch {
    /** The entry point of {@link Routed} facts (never a session's default one: a fire's answer lists those). */
    static final String ENTRY_POINT = "printeps request dispatch";
    /** The rule metadata naming a rule's {@link Spec} in the request-join network. */
    static final String METADATA = "printeps.dispatch";

    /** A fact whose field value is in the list of the pattern named {@code key}. */
    public static final class Routed {
        private final String key;
        private final Object fact;

        Routed(String key, Object fact) {
            this.key = key;
            this.fact = fact;
        }

        public String getKey() { return key; }
        public Object getFact() { return fact; }
        @Override public String toString() { return "(routed " + key + ")"; }
    }

    /** Where a rule's first pattern is dispatched: the type, the {@code in}'s field and literals, the pattern's key. */
    static final class Spec {
        final Class<?> type;
        final Property field;
        final Object[] values;
        final String key;

        Spec(Class<?> type, Property field, Object[] values, String key) {
            this.type = type;
            this.field = field;
            this.values = values;
            this.key = key;
        }
    }

    /** The fact a {@link Routed} carries: one object, so that Drools shares equal {@code from} nodes. */
    static final Function1<Object, Object> FACT = new Function1<Object, Object>() {
        public Object apply(Object routed) { return ((Routed) routed).fact; }
    };

    /**
     * For the first pattern {@code p} of a request-join build's rule: when it starts with an
     * {@code in} on literals, adds the pattern on its {@link Routed} facts to {@code items}, puts
     * its {@link Spec} in {@code metadata}, and returns the variable the pattern is to read its
     * fact from; null when it does not.
     *
     * The order of the rule's matches: the {@code from} that reads the fact passes a batch of left
     * matches on reversed, as a join does. Drools builds a rule of one pattern of alpha tests
     * ({@code terminalAlpha}: no lock-on-active, no timer) as an alpha terminal node, which gives the
     * same order as that {@code from}; any other rule gets its left input adapter, which does not
     * reverse, so a second, always-holding {@code from} ({@link PlainRequestJoins#keepOrder})
     * turns the order back.
     */
    @SuppressWarnings({"unchecked", "rawtypes"})
    static Declaration<Object> route(PlainRule rule, Map<String, Object> p, boolean terminalAlpha,
                                     List<RuleItemBuilder<?>> items, Map<String, Object> metadata) {
        List<Object> constraints = (List<Object>) p.get("constraints");
        if (constraints.isEmpty()) return null;
        Map<String, Object> c = (Map<String, Object>) constraints.get(0);
        if (!"in".equals(c.get("op")) || !(c.get("literals") instanceof List)) return null;
        Class<?> type = rule.resolve((String) p.get("type"));
        Property field = rule.context.property(type, (String) c.get("field"));
        Kind kind = PlainValues.kindOf(field.type);
        if (kind != Kind.TEXT && kind != Kind.INTEGRAL) return null;
        List<Object> literals = (List<Object>) c.get("literals");
        Object[] values = new Object[literals.size()];
        for (int i = 0; i < values.length; i++) values[i] = PlainValues.literal(literals.get(i), field.type);
        StringBuilder key = new StringBuilder(type.getName()).append(' ');
        Json.write(key, constraints, null);
        String name = key.toString();
        Property keyField = rule.context.property(Routed.class, "key");
        Declaration<Object> routed = (Declaration<Object>) (Declaration) DSL.declarationOf(
                Routed.class, rule.context.metadata(Routed.class), "$routed$" + (++rule.unnamed) + "$", DSL.entryPoint(ENTRY_POINT));
        AlphaIndex index = PatternDSL.alphaIndexedBy(String.class, Index.ConstraintType.EQUAL, keyField.index, (Function1) keyField, name);
        items.add(PatternDSL.pattern(routed).expr("printeps-routed " + name, r -> name.equals(((Routed) r).key), index,
                                                  PatternDSL.reactOn("key")));
        if (!terminalAlpha) items.add(PlainRequestJoins.keepOrder(rule));
        metadata.put(METADATA, new Spec(type, field, values, name));
        return routed;
    }

    /** The keys each value of one field reaches, for the facts of one type. */
    private static final class Table {
        final Class<?> type;
        final Property field;
        final Map<Object, LinkedHashSet<String>> keys = new HashMap<Object, LinkedHashSet<String>>();

        Table(Class<?> type, Property field) {
            this.type = type;
            this.field = field;
        }
    }

    private final List<Table> tables;
    private final Map<Class<?>, Table[]> byClass = new ConcurrentHashMap<Class<?>, Table[]>();

    private RequestDispatch(List<Table> tables) {
        this.tables = tables;
    }

    /** The dispatch of {@code kb}'s rules (their {@link #METADATA}); null when none is dispatched. */
    static RequestDispatch of(KieBase kb) {
        Map<String, Table> tables = new LinkedHashMap<String, Table>();
        for (KiePackage p : kb.getKiePackages()) {
            for (org.kie.api.definition.rule.Rule r : p.getRules()) {
                Object meta = r.getMetaData().get(METADATA);
                if (!(meta instanceof Spec)) continue;
                Spec s = (Spec) meta;
                Table t = tables.computeIfAbsent(s.type.getName() + "\0" + s.field.name, k -> new Table(s.type, s.field));
                for (Object v : s.values) t.keys.computeIfAbsent(v, k -> new LinkedHashSet<String>()).add(s.key);
            }
        }
        return tables.isEmpty() ? null : new RequestDispatch(new ArrayList<Table>(tables.values()));
    }

    /** How many patterns (keys) are dispatched. */
    int patterns() {
        java.util.Set<String> keys = new java.util.HashSet<String>();
        for (Table t : tables) for (LinkedHashSet<String> k : t.keys.values()) keys.addAll(k);
        return keys.size();
    }

    /** The entry point {@link Routed} facts go to in {@code session}. */
    EntryPoint routes(KieSession session) {
        return session.getEntryPoint(ENTRY_POINT);
    }

    /** Inserts the {@link Routed} facts of {@code f} (one per key whose list holds its value), after {@code f} itself. */
    void route(EntryPoint routes, Object f) {
        for (Table t : tablesOf(f.getClass())) {
            LinkedHashSet<String> keys = t.keys.get(t.field.apply(f));
            if (keys != null) for (String k : keys) routes.insert(new Routed(k, f));
        }
    }

    private Table[] tablesOf(Class<?> c) {
        Table[] found = byClass.get(c);
        if (found == null) {
            List<Table> of = new ArrayList<Table>();
            for (Table t : tables) if (t.type.isAssignableFrom(c)) of.add(t);
            found = of.toArray(new Table[0]);
            byClass.put(c, found);
        }
        return found;
    }
}
