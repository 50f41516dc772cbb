package org.printeps.gateway;

import java.util.ArrayList;
import java.util.Collections;
import java.util.LinkedHashMap;
import java.util.List;
import java.util.Map;
import java.util.function.Supplier;

import org.drools.model.DSL;
import org.drools.model.Declaration;
import org.drools.model.DeclarationSource;
import org.drools.model.PatternDSL;
import org.drools.model.RuleItemBuilder;
import org.drools.model.Variable;
import org.drools.model.functions.Function0;
import org.drools.model.functions.Function1;
import org.drools.model.functions.Function2;
import org.drools.model.functions.Function3;
import org.drools.model.functions.Function4;
import org.drools.model.functions.Predicate1;
import org.drools.model.functions.Predicate2;

import org.printeps.gateway.PlainRules.Reject;

import static org.printeps.gateway.PlainValues.*;

/**
 * The {@code not}, {@code exists} and accumulates of a rule in a request-join network
 * ({@link RequestFacts}): each is one {@code from} that evaluates its pattern over the request's
 * facts when the rule's left side has a match, and gives what the rule base's own node gives that
 * match — a marker when {@code not}/{@code exists} hold, the accumulate function's result
 * (Drools' own function, over the candidates in the order a right memory holds them), or nothing.
 *
 * Why one {@code from} and not Drools' {@code not ( … from … )}: that builds a subnetwork, whose
 * tuples reach the rule in another order than the rule base's own node sends them (a rule's
 * matches would fire in another order), and Drools 8.31 fails deleting through shared subnetworks
 * of a reused session (a NullPointerException in {@code SegmentPropagator.processPeerDeletes}).
 * A {@code from} in the place of the node, shared exactly when the node would be (same pattern,
 * constraints and function: {@link Derived#equals}), keeps the network's shape and order.
 */
final class PlainRequestJoins {
    private PlainRequestJoins() {}

    /** A constraint of a pattern read from the request: its id, and its test of a fact (and of a bound value). */
    static final class Test {
        final String id;
        final Predicate1<Object> alpha;
        final Predicate2<Object, Object> beta;
        final String ref;

        Test(String id, Predicate1<Object> alpha, Predicate2<Object, Object> beta, String ref) {
            this.id = id;
            this.alpha = alpha;
            this.beta = beta;
            this.ref = ref;
        }
    }

    /** {@code not Type( … )} / {@code exists Type( … )} read from the request. */
    @SuppressWarnings("unchecked")
    static RuleItemBuilder<?> negation(PlainRule rule, Map<String, Object> p, boolean not) {
        if (!((List<Object>) p.get("binds")).isEmpty()) throw new Reject("a binding inside not/exists in a request-join build");
        Read read = read(rule, p, null);
        Derived derived = new Derived(not ? "not" : "exists", read, null, null, null);
        Declaration<Object> marker = (Declaration<Object>) (Declaration) DSL.declarationOf(
                RequestFacts.Marker.class, "$request$" + (++rule.unnamed) + "$", source(rule, read, derived));
        return PatternDSL.pattern(marker);
    }

    /**
     * The declaration of an accumulate's result read from the request: {@code function} (Drools'
     * accumulate function) over the source pattern's candidates, of {@code arg} (a field of the
     * fact) or of {@code constant} ({@code count( 1 )}).
     */
    @SuppressWarnings({"unchecked", "rawtypes"})
    static Declaration<Object> accumulate(PlainRule rule, Map<String, Object> sourceSpec, String name, Class<?> resultType,
                                          String function, Supplier<?> make, String argField, Object constant) {
        Read read = read(rule, sourceSpec, new ArrayList<Object>());
        Function1<Object, Object> arg = argField == null ? null : rule.context.property(read.type, argField);
        Derived derived = new Derived(function, read, make, arg, constant);
        return (Declaration<Object>) (Declaration) DSL.declarationOf(resultType, rule.context.metadata(resultType), name,
                                                                     source(rule, read, derived));
    }

    /**
     * A {@code from} that always holds, to keep a node's order: Drools' accumulate node sends a
     * batch of matches on in the order they came (it collects them, then passes them on), while a
     * join, {@code not}, {@code exists} or {@code from} node sends them in the reverse order. After
     * an accumulate read from the request (a {@code from}), and after a {@link #linkGuard}, a
     * second {@code from} gives the order back.
     */
    @SuppressWarnings({"unchecked", "rawtypes"})
    static RuleItemBuilder<?> keepOrder(PlainRule rule) {
        Declaration<Object> marker = (Declaration<Object>) (Declaration) DSL.declarationOf(
                RequestFacts.Marker.class, "$request$" + (++rule.unnamed) + "$",
                (DeclarationSource) DSL.from((Function0) Holds.INSTANCE));
        return PatternDSL.pattern(marker);
    }

    /**
     * Before a join or {@code exists} read from the request in an auto-focus rule: {@code exists}
     * a fact of its type passing its literal tests. Why: Drools evaluates auto-focus rules in the
     * order they get linked, and each one that matches puts its agenda group on top of the focus
     * stack, so that order decides which group fires first. The rule base's own join or
     * {@code exists} node links its rule only once such a fact is in its memory; this node does
     * the same (its facts staged, as the rule base's node does, in these rules only), and
     * {@link #keepOrder} after it gives the pattern its matches in the order they came.
     */
    @SuppressWarnings("unchecked")
    static void linkGuard(PlainRule rule, Map<String, Object> p, List<RuleItemBuilder<?>> items) {
        List<Object> literal = new ArrayList<Object>();
        for (Object one : (List<Object>) p.get("constraints")) {
            if (!((Map<String, Object>) one).containsKey("ref")) literal.add(one);
        }
        Map<String, Object> guard = new LinkedHashMap<String, Object>(p);
        guard.put("var", null);
        guard.put("constraints", literal);
        guard.put("binds", Collections.emptyList());
        items.add(rule.inner(() -> (RuleItemBuilder<?>) DSL.exists(rule.pattern(guard, null))));
    }

    /** The source of {@link #keepOrder}: one marker for every match (all equal, so shared as the node before). */
    static final class Holds implements Function0<Object> {
        static final Holds INSTANCE = new Holds();

        public Object apply() { return Derived.HOLDS; }

        @Override public boolean equals(Object o) { return o instanceof Holds; }
        @Override public int hashCode() { return 17; }
    }

    /** A pattern's type and constraints, as the rule base's own build makes them (not read from the request). */
    static final class Read {
        Class<?> type;
        Test[] tests;
        List<String> refs;
        RequestFacts.Keyed keyed;
        int keyRef = -1;
    }

    @SuppressWarnings("unchecked")
    private static Read read(PlainRule rule, Map<String, Object> p, List<Object> binds) {
        Read read = new Read();
        rule.recording = new ArrayList<Test>();
        try {
            rule.inner(() -> {
                PatternDSL.PatternDef<Object> def = rule.pattern(p, binds);
                read.type = rule.varTypes.get(def.getFirstVariable().getName());
                return def;
            });
            read.tests = rule.recording.toArray(new Test[0]);
        } finally {
            rule.recording = null;
        }
        Map<String, Integer> refs = new LinkedHashMap<String, Integer>();
        for (Test t : read.tests) if (t.ref != null) refs.putIfAbsent(t.ref, refs.size());
        read.refs = new ArrayList<String>(refs.keySet());
        if (read.refs.size() > 4) throw new Reject("a pattern read from the request with more than four variables");
        RequestFacts.KeyedSource keyed = rule.requestKey(read.type, p);  // the request's facts, narrowed by an equality join
        if (keyed != null) {
            read.keyed = keyed.keyed;
            read.keyRef = refs.get(keyed.ref);
        }
        return read;
    }

    @SuppressWarnings({"unchecked", "rawtypes"})
    private static DeclarationSource source(PlainRule rule, Read read, Derived derived) {
        List<Variable> vars = new ArrayList<Variable>();
        for (String ref : read.refs) vars.add(rule.vars.get(ref));
        switch (vars.size()) {
            case 0: return (DeclarationSource) DSL.from((Function0) derived);
            case 1: return (DeclarationSource) DSL.from(vars.get(0), (Function1) derived);
            case 2: return (DeclarationSource) DSL.from(vars.get(0), vars.get(1), (Function2) derived);
            case 3: return (DeclarationSource) DSL.from(vars.get(0), vars.get(1), vars.get(2), (Function3) derived);
            default: return (DeclarationSource) DSL.from(vars.get(0), vars.get(1), vars.get(2), vars.get(3), (Function4) derived);
        }
    }

    /**
     * What a {@code not}, {@code exists} or accumulate gives one left match, from the request's
     * facts. Equal (and so shared by Drools) exactly when the node it stands for would be: the same
     * kind or function, type, constraint ids and argument.
     */
    static final class Derived implements Function0<Object>, Function1<Object, Object>, Function2<Object, Object, Object>,
            Function3<Object, Object, Object, Object>, Function4<Object, Object, Object, Object, Object> {
        private static final List<Object> NOTHING = Collections.emptyList();
        private static final List<Object> HOLDS = Collections.<Object>singletonList(RequestFacts.Marker.INSTANCE);

        final String kind;
        final Read read;
        final Supplier<?> make;
        final Function1<Object, Object> arg;
        final Object constant;
        final String signature;
        final int[] refOf;

        Derived(String kind, Read read, Supplier<?> make, Function1<Object, Object> arg, Object constant) {
            this.kind = kind;
            this.read = read;
            this.make = make;
            this.arg = arg;
            this.constant = constant;
            StringBuilder s = new StringBuilder(kind).append('|').append(read.type.getName());
            for (Test t : read.tests) s.append('|').append(t.id);
            s.append('|').append(arg instanceof Property ? ((Property) arg).name : String.valueOf(constant));
            this.signature = s.toString();
            this.refOf = new int[read.tests.length];
            for (int k = 0; k < refOf.length; k++) refOf[k] = read.tests[k].ref == null ? -1 : read.refs.indexOf(read.tests[k].ref);
        }

        public Object apply() { return derive(new Object[0]); }
        public Object apply(Object a) { return derive(new Object[] {a}); }
        public Object apply(Object a, Object b) { return derive(new Object[] {a, b}); }
        public Object apply(Object a, Object b, Object c) { return derive(new Object[] {a, b, c}); }
        public Object apply(Object a, Object b, Object c, Object d) { return derive(new Object[] {a, b, c, d}); }

        @SuppressWarnings({"unchecked", "rawtypes"})
        private Object derive(Object[] refs) {
            List<Object> candidates = read.keyed != null
                    ? RequestFacts.read(read.keyed, read.keyed.value.apply(refs[read.keyRef]))
                    : RequestFacts.read(read.type);
            try {
                if (make == null) {
                    boolean any = false;
                    for (Object c : candidates) {
                        if (passes(c, refs)) {
                            any = true;
                            break;
                        }
                    }
                    return any == kind.equals("exists") ? HOLDS : NOTHING;
                }
                org.kie.api.runtime.rule.AccumulateFunction f = (org.kie.api.runtime.rule.AccumulateFunction) make.get();
                java.io.Serializable context = f.createContext();
                f.init(context);
                for (Object c : candidates) {
                    if (passes(c, refs)) f.accumulate(context, arg == null ? constant : arg.apply(c));
                }
                Object result = f.getResult(context);
                return result == null ? NOTHING : Collections.singletonList(result);
            } catch (RuntimeException e) {
                throw e;
            } catch (Exception e) {
                throw new IllegalStateException(e);
            }
        }

        private boolean passes(Object candidate, Object[] refs) throws Exception {
            Test[] tests = read.tests;
            for (int k = 0; k < tests.length; k++) {
                boolean ok = tests[k].alpha != null ? tests[k].alpha.test(candidate) : tests[k].beta.test(candidate, refs[refOf[k]]);
                if (!ok) return false;
            }
            return true;
        }

        @Override public boolean equals(Object o) { return o instanceof Derived && ((Derived) o).signature.equals(signature); }
        @Override public int hashCode() { return signature.hashCode(); }
    }
}
