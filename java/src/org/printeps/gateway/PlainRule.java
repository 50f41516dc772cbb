package org.printeps.gateway;

import java.util.ArrayList;
import java.util.Collections;
import java.util.HashMap;
import java.util.HashSet;
import java.util.LinkedHashMap;
import java.util.List;
import java.util.Map;
import java.util.Set;

import org.drools.model.AlphaIndex;
import org.drools.model.BetaIndex;
import org.drools.model.DSL;
import org.drools.model.Declaration;
import org.drools.model.Index;
import org.drools.model.PatternDSL;
import org.drools.model.Rule;
import org.drools.model.RuleItemBuilder;
import org.drools.model.functions.Function1;
import org.drools.model.functions.Predicate1;
import org.drools.model.functions.Predicate2;

import org.printeps.gateway.PlainRules.Context;
import org.printeps.gateway.PlainRules.Reject;

import static org.printeps.gateway.PlainValues.*;

/**
 * One plain rule built from its description: its patterns and their constraints, bindings,
 * {@code not}/{@code exists} and attributes here; its accumulates in {@link PlainAccumulates}; its
 * then-part in {@link PlainThen}. The variables bound so far (and their static types, as the
 * executable model declares them) are what the later parts read.
 */
final class PlainRule {
    final Context context;
    final Map<String, Object> spec;
    final String pkg;
    final List<String> imports;
    final Map<String, Declaration<Object>> vars = new HashMap<String, Declaration<Object>>();
    final Map<String, Class<?>> varTypes = new HashMap<String, Class<?>>();
    /** Variables whose static type in the generated code is not known here (accumulate results). */
    final Set<String> uncertain = new HashSet<String>();
    final PlainAccumulates accumulates = new PlainAccumulates(this);
    int unnamed = 0;
    /**
     * Whether the pattern being built reads its facts from the request ({@link RequestFacts}):
     * in a request-join build ({@link Context#requestJoins}), every pattern of the rule's conditions
     * after the first, including those inside {@code not}, {@code exists} and accumulates.
     */
    boolean fromRequest = false;

    @SuppressWarnings("unchecked")
    PlainRule(Context context, Map<String, Object> spec) {
        this.context = context;
        this.spec = spec;
        this.pkg = (String) spec.get("package");
        Object imports = spec.get("imports");
        this.imports = imports == null ? Collections.<String>emptyList() : (List<String>) imports;
    }

    @SuppressWarnings("unchecked")
    Rule build() {
        List<RuleItemBuilder<?>> items = new ArrayList<RuleItemBuilder<?>>();
        boolean first = true;
        Map<String, Object> attributeSpec = (Map<String, Object>) spec.get("attributes");
        boolean eager = attributeSpec != null && Boolean.TRUE.equals(attributeSpec.get("auto-focus"));
        Map<String, Object> metadata = new LinkedHashMap<String, Object>();
        Object guarded = spec.get("guardedPrefix");  // opens as an auto-focus rule does: guarded as it is (shared_patterns.py)
        int guardedPrefix = guarded instanceof Number ? ((Number) guarded).intValue() : 0;
        boolean shared = Boolean.TRUE.equals(spec.get("firstShared"));  // another rule opens with this pattern: share it as the rule base does
        int position = 0;
        for (Object element : (List<Object>) spec.get("lhs")) {
            Map<String, Object> e = (Map<String, Object>) element;
            boolean guard = eager || position < guardedPrefix;
            position++;
            fromRequest = context.requestJoins && !first;
            Declaration<Object> routedBy = null;  // the Routed facts a dispatched first pattern reads its fact from
            if (first && context.requestJoins && !eager && !shared && e.containsKey("pattern")) {
                boolean terminalAlpha = ((List<Object>) spec.get("lhs")).size() == 1
                        && !Boolean.TRUE.equals(attributeSpec == null ? null : attributeSpec.get("lock-on-active"));
                routedBy = RequestDispatch.route(this, (Map<String, Object>) e.get("pattern"), terminalAlpha, items, metadata);
            }
            first = false;
            boolean linksOnFacts = fromRequest && guard && (e.containsKey("pattern") || e.containsKey("exists"));
            if (linksOnFacts) {
                PlainRequestJoins.linkGuard(this, (Map<String, Object>) e.get(e.containsKey("pattern") ? "pattern" : "exists"), items);
                items.add(PlainRequestJoins.keepOrder(this));
            }
            condition(e, routedBy, items);
        }
        items.add(new PlainThen(this).consequence((List<Object>) spec.get("rhs")));
        Object salience = spec.get("salience");
        Map<Rule.Attribute, Object> attributes = new LinkedHashMap<Rule.Attribute, Object>();
        if (salience != null) attributes.put(Rule.Attribute.SALIENCE, Integer.valueOf(((Number) salience).intValue()));
        attributes(attributes, (Map<String, Object>) spec.get("attributes"));
        return DroolsInternals.rule(pkg, (String) spec.get("name"), attributes, metadata, items.toArray(new RuleItemBuilder<?>[0]));
    }

    /** One condition element of a rule or query, added to {@code items} (a pattern reads its fact
     *  from {@code routedBy}'s Routed facts when not null: {@link RequestDispatch}). */
    @SuppressWarnings("unchecked")
    private void condition(Map<String, Object> e, Declaration<Object> routedBy, List<RuleItemBuilder<?>> items) {
        if (e.containsKey("pattern")) {
            items.add(pattern((Map<String, Object>) e.get("pattern"), null, routedBy));
        } else if (e.containsKey("accumulate")) {
            accumulates.accumulate((Map<String, Object>) e.get("accumulate"), items);
        } else if (e.containsKey("not") || e.containsKey("exists")) {
            items.add(negation(e));
        } else if (e.containsKey("fromAccumulate")) {
            accumulates.fromAccumulate((Map<String, Object>) e.get("fromAccumulate"), items);
        } else {
            throw new Reject("unknown condition " + e.keySet());
        }
    }

    /**
     * A query without parameters ({@code "query": true}): its conditions built as a rule's are
     * (the same patterns, indexes, accumulates, not/exists), ending in a query instead of a
     * consequence; its bound variables are what a row of its results reads.
     */
    @SuppressWarnings("unchecked")
    org.drools.model.Query buildQuery() {
        List<org.drools.model.view.ViewItemBuilder<?>> items = new ArrayList<org.drools.model.view.ViewItemBuilder<?>>();
        for (Object element : (List<Object>) spec.get("lhs")) {
            Map<String, Object> e = (Map<String, Object>) element;
            List<RuleItemBuilder<?>> built = new ArrayList<RuleItemBuilder<?>>();
            condition(e, null, built);
            for (RuleItemBuilder<?> item : built) {
                if (!(item instanceof org.drools.model.view.ViewItemBuilder)) throw new Reject("a query condition of another kind");
                items.add((org.drools.model.view.ViewItemBuilder<?>) item);
            }
        }
        return PatternDSL.query(pkg, (String) spec.get("name")).build(items.toArray(new org.drools.model.view.ViewItemBuilder<?>[0]));
    }

    Class<?> resolve(String name) {
        List<String> candidates = new ArrayList<String>();
        if (name.contains(".")) {
            candidates.add(name);
        } else {
            for (String imp : imports) {
                if (imp.endsWith("." + name)) candidates.add(imp);
            }
            candidates.add(pkg.isEmpty() ? name : pkg + "." + name);
            for (String imp : imports) {
                if (imp.endsWith(".*")) candidates.add(imp.substring(0, imp.length() - 1) + name);
            }
        }
        for (String c : candidates) {
            try {
                return Class.forName(c, false, context.loader);
            } catch (ClassNotFoundException | LinkageError e) {
                // the next candidate
            }
        }
        throw new Reject("type " + name + " not found");
    }

    /**
     * The class a then-part's static call names by its simple name, if javac reads it as
     * {@code java.lang.<name>}: no single-type import, type of the rule's package or on-demand
     * import of that name shadows it (or makes it ambiguous). Anything else goes to the compiler.
     */
    Class<?> javaLang(String name) {
        for (String imp : imports) {
            if (imp.endsWith("." + name) && !imp.equals("java.lang." + name)) throw new Reject("the import " + imp);
        }
        List<String> shadows = new ArrayList<String>();
        shadows.add(pkg.isEmpty() ? name : pkg + "." + name);
        for (String imp : imports) {
            if (imp.endsWith(".*") && !imp.equals("java.lang.*")) shadows.add(imp.substring(0, imp.length() - 1) + name);
        }
        for (String c : shadows) {
            try {
                Class.forName(c, false, context.loader);
                throw new Reject("the class " + c + " hides java.lang." + name);
            } catch (ClassNotFoundException | LinkageError e) {
                // not there: java.lang's stays visible
            }
        }
        try {
            return Class.forName("java.lang." + name, false, context.loader);
        } catch (ClassNotFoundException | LinkageError e) {
            throw new Reject("no class java.lang." + name);
        }
    }

    PatternDSL.PatternDef<Object> pattern(Map<String, Object> p, List<Object> binds) {
        return pattern(p, binds, null);
    }

    /** {@link #pattern(Map, List)}, its fact read from {@code routedBy}'s when not null ({@link RequestDispatch}). */
    @SuppressWarnings({"unchecked", "rawtypes"})
    PatternDSL.PatternDef<Object> pattern(Map<String, Object> p, List<Object> binds, Declaration<Object> routedBy) {
        Class<?> type = resolve((String) p.get("type"));
        String var = (String) p.get("var");
        String name = var != null ? var : "$pattern_" + type.getSimpleName() + "$" + (++unnamed) + "$";
        if (vars.containsKey(name)) throw new Reject("variable " + name + " bound twice");
        org.drools.model.DeclarationSource source = fromRequest ? requestSource(type, p)
                : routedBy != null ? DSL.from((org.drools.model.Variable) routedBy, RequestDispatch.FACT) : null;
        Declaration<Object> decl = source != null
                ? (Declaration<Object>) (Declaration) DSL.declarationOf(type, context.metadata(type), name, source)
                : (Declaration<Object>) (Declaration) DSL.declarationOf(type, context.metadata(type), name);
        PatternDSL.PatternDef<Object> def = PatternDSL.pattern(decl);
        for (Object c : (List<Object>) p.get("constraints")) {
            def = constraint(def, type, (Map<String, Object>) c);
        }
        vars.put(name, decl);
        varTypes.put(name, type);
        if (binds != null) {
            for (Object b : (List<Object>) p.get("binds")) binds.add(b);
        } else {
            for (Object b : (List<Object>) p.get("binds")) def = bindField(def, type, (Map<String, Object>) b);
        }
        return def;
    }

    /**
     * Where a pattern of a request-join build reads its facts: the request's facts of its type,
     * narrowed by the first equality join ({@link #requestKey}); the pattern's constraints still
     * decide (see {@link RequestFacts.Keyed}).
     */
    @SuppressWarnings({"unchecked", "rawtypes"})
    org.drools.model.DeclarationSource requestSource(Class<?> type, Map<String, Object> p) {
        RequestFacts.KeyedSource key = requestKey(type, p);
        return key == null ? DSL.from(new RequestFacts.All(type))
                           : DSL.from((org.drools.model.Variable) vars.get(key.ref), key.keyed);
    }

    /**
     * The first equality of the pattern with a variable bound before ({@code applicant == $id},
     * {@code applicant == $a.id}) on a text, int or boolean field (whose {@code equals} is the
     * constraint's equality), as an index of the request's facts; null if there is none.
     */
    @SuppressWarnings("unchecked")
    RequestFacts.KeyedSource requestKey(Class<?> type, Map<String, Object> p) {
        for (Object one : (List<Object>) p.get("constraints")) {
            Map<String, Object> c = (Map<String, Object>) one;
            String ref = (String) c.get("ref");
            if (!"==".equals(c.get("op")) || ref == null || !vars.containsKey(ref)) continue;
            Property field = context.property(type, (String) c.get("field"));
            Function1<Object, Object> value;
            Class<?> valueType;
            if (c.containsKey("refField")) {
                Property other = context.property(varTypes.get(ref), (String) c.get("refField"));
                value = other;
                valueType = other.type;
            } else if (boundFields.containsKey(ref)) {
                value = IDENTITY;
                valueType = boundFields.get(ref).type;
            } else {
                continue;
            }
            Kind kind = kindOf(field.type);
            if (kind == Kind.DECIMAL || kindOf(valueType) != kind) continue;
            return new RequestFacts.KeyedSource(new RequestFacts.Keyed(type, field, value), ref);
        }
        return null;
    }

    @SuppressWarnings({"unchecked", "rawtypes"})
    PatternDSL.PatternDef<Object> constraint(PatternDSL.PatternDef<Object> def, Class<?> type, Map<String, Object> c) {
        Property field = context.property(type, (String) c.get("field"));
        String operator = (String) c.get("op");
        if (operator.endsWith("in") || operator.endsWith("matches")) return operatorConstraint(def, type, field, c);
        if (c.containsKey("ref") && !c.containsKey("refField")) return boundFieldConstraint(def, type, field, c);
        Index.ConstraintType ct = constraintType((String) c.get("op"));
        Kind kind = comparable(kindOf(field.type), ct);
        if (c.containsKey("literal")) {
            Object value = literal(c.get("literal"), field.type);
            Predicate1<Object> test = fact -> compare(kind, ct, field.apply(fact), value);
            String exprId = exprId(type, field, kind, ct, javaText(c.get("literal"), field.type));
            AlphaIndex index = PatternDSL.alphaIndexedBy((Class) field.type, ct, field.index, (Function1) field, value);
            record(exprId, test, null, null);
            return def.expr(exprId, test, index, PatternDSL.reactOn(field.name));
        }
        String ref = (String) c.get("ref");
        Declaration<Object> bound = vars.get(ref);
        if (bound == null) throw new Reject("variable " + ref + " is not a pattern bound before");
        Property other = context.property(varTypes.get(ref), (String) c.get("refField"));
        if (kindOf(other.type) != kind) {
            throw new Reject("comparing " + field.type.getName() + " with " + other.type.getName());
        }
        Predicate2<Object, Object> test = (fact, joined) -> compare(kind, ct, field.apply(fact), other.apply(joined));
        String exprId = exprId(type, field, kind, ct, ref + "." + other.getter.getName() + "()");
        BetaIndex index = PatternDSL.betaIndexedBy((Class) field.type, ct, field.index, (Function1) field,
                                                   (Function1) other, other.type);
        record(exprId, null, test, ref);
        return def.expr(exprId, bound, test, index, PatternDSL.reactOn(field.name));
    }


    // ---- shapes of format 2: bound fields, in/matches, not/exists, from accumulate, attributes

    /** The field each variable bound to a field ({@code $id : id}) reads, and its declared type. */
    final Map<String, Property> boundFields = new HashMap<String, Property>();

    /** {@code $id : id}: a variable of the field's boxed type, as the executable model declares it. */
    @SuppressWarnings({"unchecked", "rawtypes"})
    PatternDSL.PatternDef<Object> bindField(PatternDSL.PatternDef<Object> def, Class<?> type, Map<String, Object> b) {
        String name = (String) b.get("var");
        if (vars.containsKey(name)) throw new Reject("variable " + name + " bound twice");
        Property field = context.property(type, (String) b.get("field"));
        Class<?> box = boxed(field.type);
        Declaration<Object> decl = (Declaration<Object>) (Declaration) DSL.declarationOf(box, context.metadata(box), name);
        vars.put(name, decl);
        varTypes.put(name, box);
        boundFields.put(name, field);
        return def.bind(decl, (Function1) field, PatternDSL.reactOn(field.name));
    }

    /**
     * {@code applicant == $id} with {@code $id} bound to a field: a beta constraint indexed as the
     * executable model indexes it. Its generated code also reacts to a property of this pattern's
     * class that has the bound field's name ({@code $id : id} makes {@code Loan( applicant == $id )}
     * react to {@code Loan.id} too); the same mask is given here.
     */
    @SuppressWarnings({"unchecked", "rawtypes"})
    PatternDSL.PatternDef<Object> boundFieldConstraint(PatternDSL.PatternDef<Object> def, Class<?> type, Property field,
                                                       Map<String, Object> c) {
        String ref = (String) c.get("ref");
        Property source = boundFields.get(ref);
        Declaration<Object> bound = vars.get(ref);
        if (bound == null || source == null) throw new Reject("variable " + ref + " is not a field bound before");
        Index.ConstraintType ct = constraintType((String) c.get("op"));
        Kind kind = comparable(kindOf(field.type), ct);
        if (kindOf(source.type) != kind) {
            throw new Reject("comparing " + field.type.getName() + " with " + source.type.getName());
        }
        Predicate2<Object, Object> test = (fact, value) -> compare(kind, ct, field.apply(fact), value);
        String exprId = exprId(type, field, kind, ct, ref);
        BetaIndex index = PatternDSL.betaIndexedBy((Class) field.type, ct, field.index, (Function1) field,
                                                   (Function1) IDENTITY, source.type);
        List<String> react = new ArrayList<String>();
        if (!source.name.equals(field.name) && isProperty(type, source.name)) react.add(source.name);
        react.add(field.name);
        record(exprId, null, test, ref);
        return def.expr(exprId, bound, test, index, PatternDSL.reactOn(react.toArray(new String[0])));
    }

    boolean isProperty(Class<?> type, String name) {
        try {
            context.metadata(type).getPropertyIndex(name);
            return true;
        } catch (RuntimeException e) {
            return false;
        }
    }

    /**
     * {@code region in ( "a", "b" )}, {@code not in}, {@code matches "re"}, {@code not matches}:
     * the executable model's operator objects, with its constraint id, and no index (so never a
     * hashed alpha node). {@code in} only on text and int fields with literals of their type: the
     * operator compares with {@code equals}, so other pairings depend on the compiler's boxing.
     */
    @SuppressWarnings("unchecked")
    PatternDSL.PatternDef<Object> operatorConstraint(PatternDSL.PatternDef<Object> def, Class<?> type, Property field,
                                                     Map<String, Object> c) {
        String op = (String) c.get("op");
        boolean negated = op.startsWith("not ");
        Kind kind = kindOf(field.type);
        org.drools.model.functions.Operator<Object, Object> operator;
        String operatorName;
        List<Object> literals;
        if (op.endsWith("matches")) {
            if (kind != Kind.TEXT) throw new Reject("matches on a " + field.type.getName() + " field");
            operator = (org.drools.model.functions.Operator<Object, Object>) (Object) org.drools.model.operators.MatchesOperator.INSTANCE;
            operatorName = "MatchesOperator";
            literals = Collections.singletonList(c.get("literal"));
        } else if (op.endsWith("in")) {
            if (kind != Kind.TEXT && kind != Kind.INTEGRAL) throw new Reject("in on a " + field.type.getName() + " field");
            operator = (org.drools.model.functions.Operator<Object, Object>) (Object) org.drools.model.operators.InOperator.INSTANCE;
            operatorName = "InOperator";
            literals = (List<Object>) c.get("literals");
        } else {
            throw new Reject("operator " + op);
        }
        Object[] values = new Object[literals.size()];
        StringBuilder java = new StringBuilder(negated ? "!" : "").append("D.eval(org.drools.model.operators.")
                .append(operatorName).append(".INSTANCE, _this.").append(field.getter.getName()).append("()");
        for (int i = 0; i < values.length; i++) {
            values[i] = literal(literals.get(i), field.type);
            java.append(", ").append(javaText(literals.get(i), field.type));
        }
        java.append(")");
        String exprId = DroolsInternals.generatedExprId(type, java);
        Predicate1<Object> holds = operatorTest(operator, field, values);
        Predicate1<Object> test = negated ? fact -> !holds.test(fact) : holds;
        record(exprId, test, null, null);
        return def.expr(exprId, test, PatternDSL.reactOn(field.name));
    }

    /**
     * The operator's test of a fact. {@code matches} as {@link org.drools.model.operators.MatchesOperator}
     * decides it (false on null, else {@code String.matches}), with the expression compiled once:
     * {@code String.matches} compiles it at every call, and an alpha node under the type node runs it
     * for every fact of the type (at 10,000 business rules ~900 rules start with a {@code matches}).
     * An expression that does not compile is left to the operator, so it fails when Drools' test would.
     */
    static Predicate1<Object> operatorTest(org.drools.model.functions.Operator<Object, Object> operator,
                                           Property field, Object[] values) {
        if (operator == (Object) org.drools.model.operators.MatchesOperator.INSTANCE) {
            java.util.regex.Pattern regex;
            try {
                regex = java.util.regex.Pattern.compile((String) values[0]);
            } catch (java.util.regex.PatternSyntaxException e) {
                regex = null;
            }
            if (regex != null) {
                java.util.regex.Pattern compiled = regex;
                return fact -> {
                    Object text = field.apply(fact);
                    return text != null && compiled.matcher((String) text).matches();
                };
            }
        }
        return fact -> DSL.eval(operator, field.apply(fact), values);
    }

    /**
     * What {@code build} makes as the rule base's own build makes it (nothing read from the
     * request), the variables bound inside it not visible after it: a pattern inside a {@code not}
     * or {@code exists}, and a request-join build's patterns inside accumulates and its linking guards.
     */
    <T> T inner(java.util.function.Supplier<T> build) {
        Set<String> before = new HashSet<String>(vars.keySet());
        boolean outer = fromRequest;
        fromRequest = false;
        try {
            return build.get();
        } finally {
            fromRequest = outer;
            vars.keySet().retainAll(before);
            varTypes.keySet().retainAll(before);
        }
    }

    /** The constraints of the pattern being built, when {@link #recording} (see {@link PlainRequestJoins}). */
    List<PlainRequestJoins.Test> recording = null;

    private void record(String id, Predicate1<Object> alpha, Predicate2<Object, Object> beta, String ref) {
        if (recording != null) recording.add(new PlainRequestJoins.Test(id, alpha, beta, ref));
    }

    /** {@code not Type( … )} / {@code exists Type( … )}: nothing bound inside is visible after it. */
    @SuppressWarnings("unchecked")
    RuleItemBuilder<?> negation(Map<String, Object> e) {
        boolean not = e.containsKey("not");
        if (fromRequest) return PlainRequestJoins.negation(this, (Map<String, Object>) e.get(not ? "not" : "exists"), not);
        PatternDSL.PatternDef<Object> def = inner(() -> pattern((Map<String, Object>) e.get(not ? "not" : "exists"), null));
        return (RuleItemBuilder<?>) (not ? DSL.not(def) : DSL.exists(def));
    }


    /** A rule date as the generated code computes it; a bad one is refused with what is expected
     *  (the build checks every date before it gets here: {@code gateway.engine.rule_dates}). */
    static Object date(String text) {
        String problem = PlainRules.ruleDateProblem(text);
        if (problem != null) throw new Reject(problem);
        return DroolsInternals.ruleDate(text);
    }

    /** The attributes besides salience, as the executable model sets them. */
    @SuppressWarnings({"unchecked", "rawtypes"})
    void attributes(Map<Rule.Attribute, Object> into, Map<String, Object> attributes) {
        if (attributes == null) return;
        for (Map.Entry<String, Object> a : attributes.entrySet()) {
            Object v = a.getValue();
            Rule.Attribute attribute;
            switch (a.getKey()) {
                case "agenda-group": attribute = Rule.Attribute.AGENDA_GROUP; break;
                case "activation-group": attribute = Rule.Attribute.ACTIVATION_GROUP; break;
                case "auto-focus": attribute = Rule.Attribute.AUTO_FOCUS; break;
                case "no-loop": attribute = Rule.Attribute.NO_LOOP; break;
                case "lock-on-active": attribute = Rule.Attribute.LOCK_ON_ACTIVE; break;
                case "date-effective": attribute = Rule.Attribute.DATE_EFFECTIVE; v = date((String) v); break;
                case "date-expires": attribute = Rule.Attribute.DATE_EXPIRES; v = date((String) v); break;
                default: throw new Reject("attribute " + a.getKey());
            }
            into.put(attribute, v);
        }
    }

}
