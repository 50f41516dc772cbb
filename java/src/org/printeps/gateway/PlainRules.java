package org.printeps.gateway;

import java.lang.reflect.InvocationTargetException;
import java.lang.reflect.Method;
import java.lang.reflect.Modifier;
import java.util.ArrayList;
import java.util.Collections;
import java.util.HashMap;
import java.util.LinkedHashMap;
import java.util.List;
import java.util.Map;

import org.drools.model.AlphaIndex;
import org.drools.model.BetaIndex;
import org.drools.model.DSL;
import org.drools.model.Declaration;
import org.drools.model.DomainClassMetadata;
import org.drools.model.EntryPoint;
import org.drools.model.Global;
import org.drools.model.Index;
import org.drools.model.Model;
import org.drools.model.PatternDSL;
import org.drools.model.Query;
import org.drools.model.Rule;
import org.drools.model.RuleItemBuilder;
import org.drools.model.TypeMetaData;
import org.drools.model.Variable;
import org.drools.model.functions.Block0;
import org.drools.model.functions.Block1;
import org.drools.model.functions.Block2;
import org.drools.model.functions.Block3;
import org.drools.model.functions.Block4;
import org.drools.model.functions.Function1;
import org.drools.model.functions.Predicate1;
import org.drools.model.functions.Predicate2;

/**
 * Rules of the plain shapes built at run time as executable-model objects, without generating or
 * compiling Java. The rule set's Python side ({@code gateway.engine.plain_rules}) describes each
 * such rule: patterns on declared or imported types with field-versus-literal and
 * field-versus-bound-field comparisons, in/matches, not/exists, count/sum/min/max accumulates, the
 * usual rule attributes (format 2), a then-part of calls on one global with
 * literals, bound facts, their getters and text joined from those. This class builds the same
 * {@link Rule} the executable model's generated code builds: the same alpha and beta indexes,
 * property reactivity, accumulate function and constraint ids, so Drools hashes, shares and fires
 * them alike, also next to compiled rules.
 *
 * Why: generating and compiling Java costs ~11 ms of CPU per rule (10,000 rules: two minutes of
 * CPU); building the same model objects takes microseconds. A rule this class cannot build exactly
 * (an unknown field, a type it would have to convert, an ambiguous method) is reported as rejected
 * with the reason and goes through Drools' compiler, which also reports its errors with file, line
 * and column.
 */
public final class PlainRules {
    private PlainRules() {}

    /** The description format this class reads (the Python side writes the same number). */
    public static final int FORMAT = 2;

    /** What {@link #build} made: one model per package, and the rules it refused ("index\treason"). */
    public static final class Built {
        private final List<Model> models;
        private final List<String> rejected;

        Built(List<Model> models, List<String> rejected) {
            this.models = models;
            this.rejected = rejected;
        }

        public List<Model> models() { return models; }
        public String[] rejected() { return rejected.toArray(new String[0]); }
    }

    /** A rule this class cannot build exactly as the compiler would. */
    static final class Reject extends RuntimeException {
        Reject(String message) { super(message, null, false, false); }
    }

    /**
     * Builds the rules of {@code spec} (JSON: {@code {"format": 1, "rules": [...]}}) against the
     * classes of {@code loader} (the declarations unit's) and the globals of {@code declarations}.
     */
    @SuppressWarnings("unchecked")
    public static Built build(ClassLoader loader, List<Model> declarations, String spec) {
        Map<String, Object> root = (Map<String, Object>) Json.parse(spec);
        Object format = root.get("format");
        if (!(format instanceof Number) || ((Number) format).intValue() != FORMAT) {
            throw new IllegalArgumentException("plain rule description of format " + format + ", expected " + FORMAT);
        }
        Map<String, Global<?>> globals = new HashMap<String, Global<?>>();
        for (Model m : declarations) {
            for (Global<?> g : m.getGlobals()) globals.putIfAbsent(m.getPackageName() + "\0" + g.getName(), g);
        }
        Map<String, PlainModel> byPackage = new LinkedHashMap<String, PlainModel>();
        List<String> rejected = new ArrayList<String>();
        List<Object> rules = (List<Object>) root.get("rules");
        Context context = new Context(loader, globals);
        for (int k = 0; k < rules.size(); k++) {
            Map<String, Object> r = (Map<String, Object>) rules.get(k);
            try {
                Rule rule = new OneRule(context, r).build();
                byPackage.computeIfAbsent((String) r.get("package"), PlainModel::new).rules.add(rule);
            } catch (Reject e) {
                rejected.add(k + "\t" + e.getMessage());
            } catch (RuntimeException | LinkageError e) {
                rejected.add(k + "\t" + e);
            }
        }
        return new Built(new ArrayList<Model>(byPackage.values()), rejected);
    }

    // ------------------------------------------------------------------ shared state of one build

    static final class Context {
        final ClassLoader loader;
        final Map<String, Global<?>> globals;
        final Map<Class<?>, DomainClassMetadata> metadata = new HashMap<Class<?>, DomainClassMetadata>();
        final Map<String, Property> properties = new HashMap<String, Property>();

        Context(ClassLoader loader, Map<String, Global<?>> globals) {
            this.loader = loader;
            this.globals = globals;
        }

        DomainClassMetadata metadata(Class<?> type) {
            return metadata.computeIfAbsent(type, DroolsInternals::domainClassMetadata);
        }

        Property property(Class<?> type, String field) {
            return properties.computeIfAbsent(type.getName() + "\0" + field, key -> Property.of(type, field, metadata(type)));
        }
    }

    /** A readable field of a fact class: its getter, type and property index. */
    static final class Property implements Function1<Object, Object> {
        final String name;
        final Method getter;
        final Class<?> type;  // as declared (a primitive stays primitive)
        final int index;

        private Property(String name, Method getter, int index) {
            this.name = name;
            this.getter = getter;
            this.type = getter.getReturnType();
            this.index = index;
        }

        static Property of(Class<?> owner, String name, DomainClassMetadata meta) {
            Method getter = getter(owner, "get" + capitalize(name));
            if (getter == null) {
                Method is = getter(owner, "is" + capitalize(name));
                if (is != null && (is.getReturnType() == boolean.class)) getter = is;
            }
            if (getter == null) throw new Reject("no readable field '" + name + "' in " + owner.getName());
            int index;
            try {
                index = meta.getPropertyIndex(name);
            } catch (RuntimeException e) {
                throw new Reject("'" + name + "' is not a property of " + owner.getName());
            }
            return new Property(name, getter, index);
        }

        private static Method getter(Class<?> owner, String name) {
            try {
                Method m = owner.getMethod(name);
                return Modifier.isStatic(m.getModifiers()) || m.getReturnType() == void.class ? null : m;
            } catch (NoSuchMethodException e) {
                return null;
            }
        }

        public Object apply(Object fact) {
            try {
                return getter.invoke(fact);
            } catch (InvocationTargetException e) {
                throw rethrow(e.getCause());
            } catch (IllegalAccessException e) {
                throw new IllegalStateException(e);
            }
        }
    }

    static RuntimeException rethrow(Throwable t) {
        if (t instanceof RuntimeException) return (RuntimeException) t;
        if (t instanceof Error) throw (Error) t;
        return new RuntimeException(t);
    }

    static String capitalize(String s) {
        return s.isEmpty() ? s : Character.toUpperCase(s.charAt(0)) + s.substring(1);
    }

    // ------------------------------------------------------------------ values and comparisons

    /** How two values compare: by number for numeric types, by equals for the rest. */
    enum Kind { INTEGRAL, DECIMAL, TEXT, BOOLEAN }

    static Kind kindOf(Class<?> t) {
        if (t == int.class || t == Integer.class) return Kind.INTEGRAL;
        if (t == double.class || t == Double.class) return Kind.DECIMAL;
        if (t == String.class) return Kind.TEXT;
        if (t == boolean.class || t == Boolean.class) return Kind.BOOLEAN;
        throw new Reject("fields of type " + t.getName() + " are left to the compiler");
    }

    static Class<?> boxed(Class<?> t) {
        if (t == int.class) return Integer.class;
        if (t == double.class) return Double.class;
        if (t == boolean.class) return Boolean.class;
        return t;
    }

    /** A literal of the description ({"s": text} | {"n": digits} | {"b": bool}) as a value of {@code type}. */
    @SuppressWarnings("unchecked")
    static Object literal(Object spec, Class<?> type) {
        Map<String, Object> lit = (Map<String, Object>) spec;
        Kind kind = kindOf(type);
        Class<?> box = boxed(type);
        if (lit.containsKey("s")) {
            if (kind != Kind.TEXT) throw new Reject("a text literal compared with a " + type.getName() + " field");
            return lit.get("s");
        }
        if (lit.containsKey("b")) {
            if (kind != Kind.BOOLEAN) throw new Reject("a boolean literal compared with a " + type.getName() + " field");
            return lit.get("b");
        }
        String digits = (String) lit.get("n");
        if (digits == null) throw new Reject("unknown literal " + spec);
        boolean decimal = digits.contains(".");
        if (box == Integer.class && !decimal) return Integer.valueOf(digits);
        if (box == Double.class) return Double.valueOf(javaText(lit, type));
        throw new Reject("the number " + digits + " compared with a " + type.getName() + " field");
    }

    /**
     * The literal as the executable model writes it in the generated Java expression: text quoted,
     * integers as written, a number compared with a double field as a double literal. A literal
     * whose written form the compiler may print otherwise (0.10, 1e3) is left to the compiler.
     */
    @SuppressWarnings("unchecked")
    static String javaText(Object spec, Class<?> type) {
        Map<String, Object> lit = (Map<String, Object>) spec;
        if (lit.containsKey("s")) return "\"" + lit.get("s") + "\"";
        if (lit.containsKey("b")) return String.valueOf(lit.get("b"));
        String digits = (String) lit.get("n");
        if (kindOf(type) != Kind.DECIMAL) return digits;
        String text = digits.contains(".") ? digits : digits + ".0";
        if (!Double.toString(Double.parseDouble(text)).equals(text)) throw new Reject("the number " + digits);
        return text;
    }

    /**
     * The id the executable model gives a constraint ({@link DroolsInternals#constraintExprId}).
     * Constraints of equal id are one node to Drools, so a rule built here shares its nodes with a
     * compiled rule of the same constraint; a different id would make two alpha nodes of one hashed
     * value, and Drools' alpha hashing keeps only one of them.
     */
    static String exprId(Class<?> type, Property field, Kind kind, Index.ConstraintType op, String right) {
        String id = DroolsInternals.constraintExprId(type, field.getter.getName(), kind == Kind.INTEGRAL || kind == Kind.DECIMAL, op, right);
        if (id == null) throw new Reject("operator " + op);
        return id;
    }

    static Index.ConstraintType constraintType(String op) {
        switch (op) {
            case "==": return Index.ConstraintType.EQUAL;
            case "!=": return Index.ConstraintType.NOT_EQUAL;
            case ">": return Index.ConstraintType.GREATER_THAN;
            case ">=": return Index.ConstraintType.GREATER_OR_EQUAL;
            case "<": return Index.ConstraintType.LESS_THAN;
            case "<=": return Index.ConstraintType.LESS_OR_EQUAL;
            default: throw new Reject("operator " + op);
        }
    }

    /** {@code left op right}, null-safe as the executable model's EvaluationUtil: a null never orders.
     *  (On the fire path: {@code op} is parsed once, when the rule is built.) */
    static boolean compare(Kind kind, Index.ConstraintType op, Object left, Object right) {
        if (op == Index.ConstraintType.EQUAL || op == Index.ConstraintType.NOT_EQUAL) {
            boolean same;
            if (left == null || right == null) {
                same = left == right;
            } else if (kind == Kind.INTEGRAL) {
                same = ((Number) left).longValue() == ((Number) right).longValue();
            } else if (kind == Kind.DECIMAL) {
                same = ((Number) left).doubleValue() == ((Number) right).doubleValue();
            } else {
                same = left.equals(right);
            }
            return (op == Index.ConstraintType.EQUAL) == same;
        }
        if (left == null || right == null) return false;
        int c;
        if (kind == Kind.INTEGRAL) {
            c = Long.compare(((Number) left).longValue(), ((Number) right).longValue());
        } else if (kind == Kind.DECIMAL) {
            double a = ((Number) left).doubleValue(), b = ((Number) right).doubleValue();
            if (Double.isNaN(a) || Double.isNaN(b)) return false;
            c = a < b ? -1 : a > b ? 1 : 0;
        } else {
            throw new IllegalStateException("operator " + op + " on " + kind);  // refused by comparable()
        }
        switch (op) {
            case GREATER_THAN: return c > 0;
            case GREATER_OR_EQUAL: return c >= 0;
            case LESS_THAN: return c < 0;
            case LESS_OR_EQUAL: return c <= 0;
            default: throw new IllegalStateException("operator " + op);
        }
    }

    /** {@code kind} if values of it can be compared by {@code op} (text and booleans only for equality). */
    static Kind comparable(Kind kind, Index.ConstraintType op) {
        if ((kind == Kind.TEXT || kind == Kind.BOOLEAN)
                && op != Index.ConstraintType.EQUAL && op != Index.ConstraintType.NOT_EQUAL) {
            throw new Reject("operator " + op + " on " + kind);
        }
        return kind;
    }

    /** One argument of a then-part call: its value when the rule fires, from the facts it names. */
    interface Arg {
        Object value(Object[] facts) throws Exception;
    }

    /** A then-part: calls on one global, with the facts of the variables its arguments read. */
    static final class Calls {
        final Method[] methods;
        final Arg[][] args;

        Calls(Method[] methods, Arg[][] args) {
            this.methods = methods;
            this.args = args;
        }

        void run(Object target, Object... facts) throws Exception {
            for (int k = 0; k < methods.length; k++) {
                Object[] values = new Object[args[k].length];
                for (int i = 0; i < values.length; i++) values[i] = args[k][i].value(facts);
                invoke(methods[k], target, values);
            }
        }
    }

    static final Object[] NO_ARGS = new Object[0];

    /** The right side of a beta index on a bound field: the variable's value itself. */
    static final Function1<Object, Object> IDENTITY = v -> v;

    static Object invoke(Method method, Object target, Object[] values) throws Exception {
        try {
            return method.invoke(target, values);
        } catch (InvocationTargetException e) {
            Throwable cause = e.getCause();
            if (cause instanceof Exception) throw (Exception) cause;
            throw rethrow(cause);
        }
    }

    // ------------------------------------------------------------------ one rule

    static final class OneRule {
        final Context context;
        final Map<String, Object> spec;
        final String pkg;
        final List<String> imports;
        final Map<String, Declaration<Object>> vars = new HashMap<String, Declaration<Object>>();
        final Map<String, Class<?>> varTypes = new HashMap<String, Class<?>>();
        int unnamed = 0;

        @SuppressWarnings("unchecked")
        OneRule(Context context, Map<String, Object> spec) {
            this.context = context;
            this.spec = spec;
            this.pkg = (String) spec.get("package");
            Object imports = spec.get("imports");
            this.imports = imports == null ? Collections.<String>emptyList() : (List<String>) imports;
        }

        @SuppressWarnings("unchecked")
        Rule build() {
            List<RuleItemBuilder<?>> items = new ArrayList<RuleItemBuilder<?>>();
            for (Object element : (List<Object>) spec.get("lhs")) {
                Map<String, Object> e = (Map<String, Object>) element;
                if (e.containsKey("pattern")) {
                    items.add(pattern((Map<String, Object>) e.get("pattern"), null));
                } else if (e.containsKey("accumulate")) {
                    accumulate((Map<String, Object>) e.get("accumulate"), items);
                } else if (e.containsKey("not") || e.containsKey("exists")) {
                    items.add(negation(e));
                } else if (e.containsKey("fromAccumulate")) {
                    fromAccumulate((Map<String, Object>) e.get("fromAccumulate"), items);
                } else {
                    throw new Reject("unknown condition " + e.keySet());
                }
            }
            items.add(consequence((List<Object>) spec.get("rhs")));
            Object salience = spec.get("salience");
            Map<Rule.Attribute, Object> attributes = new LinkedHashMap<Rule.Attribute, Object>();
            if (salience != null) attributes.put(Rule.Attribute.SALIENCE, Integer.valueOf(((Number) salience).intValue()));
            attributes(attributes, (Map<String, Object>) spec.get("attributes"));
            return DroolsInternals.rule(pkg, (String) spec.get("name"), attributes, items.toArray(new RuleItemBuilder<?>[0]));
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

        @SuppressWarnings({"unchecked", "rawtypes"})
        PatternDSL.PatternDef<Object> pattern(Map<String, Object> p, List<Object> binds) {
            Class<?> type = resolve((String) p.get("type"));
            String var = (String) p.get("var");
            String name = var != null ? var : "$pattern_" + type.getSimpleName() + "$" + (++unnamed) + "$";
            if (vars.containsKey(name)) throw new Reject("variable " + name + " bound twice");
            Declaration<Object> decl = (Declaration<Object>) (Declaration) DSL.declarationOf(type, context.metadata(type), name);
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
            return def.expr(exprId, bound, test, index, PatternDSL.reactOn(field.name));
        }

        @SuppressWarnings({"unchecked", "rawtypes"})
        void accumulate(Map<String, Object> a, List<RuleItemBuilder<?>> items) {
            List<Object> binds = new ArrayList<Object>();
            PatternDSL.PatternDef<Object> source = pattern((Map<String, Object>) a.get("source"), binds);
            String sourceVar = source.getFirstVariable().getName();
            Class<?> type = varTypes.remove(sourceVar);  // bound inside the accumulate: not visible after it
            vars.remove(sourceVar);
            String function = (String) a.get("function");
            String arg = (String) a.get("arg");
            Variable<Object> input = null;
            for (Object b : binds) {
                Map<String, Object> bind = (Map<String, Object>) b;
                Property field = context.property(type, (String) bind.get("field"));
                if (!((String) bind.get("var")).equals(arg)) throw new Reject("a binding the accumulate does not use");
                Class<?> box = boxed(field.type);
                if (function.equals("sum") && box != Double.class) {
                    throw new Reject("sum over " + field.type.getName() + " is left to the compiler");
                }
                input = (Variable<Object>) (Variable) DSL.declarationOf(box, arg);
                source = source.bind(input, (Function1) field, PatternDSL.reactOn(field.name));
            }
            org.drools.model.functions.accumulate.AccumulateFunction fn;
            Class<?> resultType;
            if (function.equals("sum") && input != null && binds.size() == 1) {
                fn = DroolsInternals.sum(input);
                resultType = Double.class;
            } else {
                throw new Reject("accumulate function " + function + " is left to the compiler");
            }
            String resultName = (String) a.get("var");
            if (vars.containsKey(resultName)) throw new Reject("variable " + resultName + " bound twice");
            Declaration<Object> result = (Declaration<Object>) (Declaration) DSL.declarationOf(resultType, context.metadata(resultType), resultName);
            vars.put(resultName, result);
            varTypes.put(resultName, resultType);
            items.add((RuleItemBuilder<?>) DSL.accumulate(source, fn.as(result)));
            List<Object> tests = (List<Object>) a.get("constraints");
            if (!tests.isEmpty()) {
                PatternDSL.PatternDef<Object> on = PatternDSL.pattern(result);
                for (Object t : tests) {
                    Map<String, Object> c = (Map<String, Object>) t;
                    Object value = literal(c.get("literal"), double.class);
                    Index.ConstraintType op = constraintType((String) c.get("op"));
                    Predicate1<Object> test = total -> compare(Kind.DECIMAL, op, total, value);
                    on = on.expr("PLAIN:" + resultType.getName() + ":" + c.get("text"), test);
                }
                items.add(on);
            }
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
            Predicate1<Object> test = negated
                    ? fact -> !DSL.eval(operator, field.apply(fact), values)
                    : fact -> DSL.eval(operator, field.apply(fact), values);
            return def.expr(exprId, test, PatternDSL.reactOn(field.name));
        }

        /** {@code not Type( … )} / {@code exists Type( … )}: nothing bound inside is visible after it. */
        @SuppressWarnings("unchecked")
        RuleItemBuilder<?> negation(Map<String, Object> e) {
            boolean not = e.containsKey("not");
            java.util.Set<String> before = new java.util.HashSet<String>(vars.keySet());
            PatternDSL.PatternDef<Object> def = pattern((Map<String, Object>) e.get(not ? "not" : "exists"), null);
            vars.keySet().retainAll(before);
            varTypes.keySet().retainAll(before);
            return (RuleItemBuilder<?>) (not ? DSL.not(def) : DSL.exists(def));
        }

        /**
         * {@code Number( intValue >= 2 ) from accumulate( Loan( applicant == $id, $m : amount ), count( 1 ) )}:
         * the accumulate function and result type the executable model chooses
         * ({@link DroolsInternals#accumulateFunction}), every binding of the source pattern made
         * (used or not, as the generated code does), and the result pattern's comparisons of
         * {@code intValue}/{@code longValue}/{@code doubleValue} with numbers.
         */
        @SuppressWarnings({"unchecked", "rawtypes"})
        void fromAccumulate(Map<String, Object> a, List<RuleItemBuilder<?>> items) {
            Map<String, Object> resultSpec = (Map<String, Object>) a.get("result");
            String resultTypeName = (String) resultSpec.get("type");
            if (!resultTypeName.equals("Number") && !resultTypeName.equals("java.lang.Number")) {
                throw new Reject("an accumulate result of type " + resultTypeName);
            }
            java.util.Set<String> before = new java.util.HashSet<String>(vars.keySet());
            List<Object> binds = new ArrayList<Object>();
            PatternDSL.PatternDef<Object> source = pattern((Map<String, Object>) a.get("source"), binds);
            Class<?> type = varTypes.get(source.getFirstVariable().getName());
            vars.keySet().retainAll(before);  // bound inside the accumulate: not visible after it
            varTypes.keySet().retainAll(before);
            String function = (String) a.get("function");
            Map<String, Object> arg = (Map<String, Object>) a.get("arg");
            String argVar = (String) arg.get("var");
            Variable<Object> input = null;
            Class<?> inputType = Integer.class;
            for (Object b : binds) {
                Map<String, Object> bind = (Map<String, Object>) b;
                Property field = context.property(type, (String) bind.get("field"));
                Class<?> box = boxed(field.type);
                Variable<Object> v = (Variable<Object>) (Variable) DSL.declarationOf(box, (String) bind.get("var"));
                source = source.bind(v, (Function1) field, PatternDSL.reactOn(field.name));
                if (bind.get("var").equals(argVar)) {
                    input = v;
                    inputType = box;
                }
            }
            org.drools.model.Argument<?> argument;
            if (argVar != null) {
                if (input == null) throw new Reject("an accumulate over " + argVar + ", not bound in its pattern");
                argument = input;
            } else if (function.equals("count")) {
                argument = DSL.valueOf(literal(arg, int.class));  // count( 1 )
            } else {
                throw new Reject(function + " of a constant");
            }
            java.util.function.Supplier<?> fn = DroolsInternals.accumulateFunction(function, inputType);
            if (fn == null) throw new Reject("accumulate function " + function + " over " + inputType.getName() + " is left to the compiler");
            Class<?> resultType = DroolsInternals.accumulateResultType(function);
            String resultVar = (String) resultSpec.get("var");
            String resultName = resultVar != null ? resultVar : "$pattern_Number$" + (++unnamed) + "$";
            if (vars.containsKey(resultName)) throw new Reject("variable " + resultName + " bound twice");
            Declaration<Object> result = (Declaration<Object>) (Declaration) DSL.declarationOf(resultType, context.metadata(resultType), resultName);
            items.add((RuleItemBuilder<?>) DSL.accumulate(source, DSL.accFunction(fn, argument).as(result)));
            vars.put(resultName, result);
            varTypes.put(resultName, resultType);
            List<Object> tests = (List<Object>) resultSpec.get("constraints");
            if (tests.isEmpty()) return;
            PatternDSL.PatternDef<Object> on = PatternDSL.pattern(result);
            for (Object t : tests) {
                Map<String, Object> c = (Map<String, Object>) t;
                String field = (String) c.get("field");
                Index.ConstraintType op = constraintType((String) c.get("op"));
                Predicate1<Object> test;
                if (field.equals("doubleValue")) {
                    Object value = literal(c.get("literal"), double.class);
                    test = r -> compare(Kind.DECIMAL, op, r == null ? null : ((Number) r).doubleValue(), value);
                } else if (field.equals("intValue")) {
                    Object value = literal(c.get("literal"), int.class);
                    test = r -> compare(Kind.INTEGRAL, op, r == null ? null : ((Number) r).intValue(), value);
                } else if (field.equals("longValue")) {
                    Object value = literal(c.get("literal"), int.class);
                    test = r -> compare(Kind.INTEGRAL, op, r == null ? null : ((Number) r).longValue(), value);
                } else {
                    throw new Reject("an accumulate result's " + field);
                }
                on = on.expr("PLAIN:" + resultType.getName() + ":" + c.get("text"), test);
            }
            items.add(on);
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
                    case "date-effective": attribute = Rule.Attribute.DATE_EFFECTIVE; v = DroolsInternals.ruleDate((String) v); break;
                    case "date-expires": attribute = Rule.Attribute.DATE_EXPIRES; v = DroolsInternals.ruleDate((String) v); break;
                    default: throw new Reject("attribute " + a.getKey());
                }
                into.put(attribute, v);
            }
        }

        @SuppressWarnings({"unchecked", "rawtypes"})
        RuleItemBuilder<?> consequence(List<Object> calls) {
            if (calls.isEmpty()) return DSL.execute((Block0) () -> {});
            String target = null;
            List<String> used = new ArrayList<String>();  // the variables the arguments read, in order
            Method[] methods = new Method[calls.size()];
            Arg[][] args = new Arg[calls.size()][];
            for (int k = 0; k < calls.size(); k++) {
                Map<String, Object> call = (Map<String, Object>) calls.get(k);
                String t = (String) call.get("target");
                if (target != null && !target.equals(t)) throw new Reject("calls on more than one global");
                target = t;
                List<Object> given = (List<Object>) call.get("args");
                Global<?> global = context.globals.get(pkg + "\0" + t);
                if (global == null) throw new Reject("no global " + t + " in package " + pkg);
                for (Method m : global.getType().getMethods()) {
                    if (!m.getName().equals(call.get("method")) || m.getParameterCount() != given.size()
                            || Modifier.isStatic(m.getModifiers())) continue;
                    Arg[] fitted = fit(m.getParameterTypes(), given, used);
                    if (fitted == null) continue;
                    if (methods[k] != null) throw new Reject("more than one method " + m.getName() + " fits");
                    methods[k] = m;
                    args[k] = fitted;
                }
                if (methods[k] == null) throw new Reject("no method " + call.get("method") + " of " + t + " fits");
            }
            Global<Object> global = (Global<Object>) context.globals.get(pkg + "\0" + target);
            Calls block = new Calls(methods, args);
            Variable[] v = new Variable[used.size()];
            for (int i = 0; i < v.length; i++) v[i] = vars.get(used.get(i));
            switch (v.length) {
                case 0: return DSL.on(global).execute((Block1<Object>) g -> block.run(g));
                case 1: return DSL.on(global, v[0]).execute((Block2<Object, Object>) (g, a) -> block.run(g, a));
                case 2: return DSL.on(global, v[0], v[1]).execute((Block3<Object, Object, Object>) (g, a, b) -> block.run(g, a, b));
                case 3: return DSL.on(global, v[0], v[1], v[2]).execute(
                        (Block4<Object, Object, Object, Object>) (g, a, b, c) -> block.run(g, a, b, c));
                default: throw new Reject("a then-part reading more than three variables");
            }
        }

        /** The arguments for a method with these parameter types, or null if one of them does not
         *  fit exactly as Java would pass it (no widening, no overload choice). */
        @SuppressWarnings("unchecked")
        Arg[] fit(Class<?>[] types, List<Object> given, List<String> used) {
            Arg[] out = new Arg[types.length];
            for (int k = 0; k < types.length; k++) {
                out[k] = argument((Map<String, Object>) given.get(k), types[k], used);
                if (out[k] == null) return null;
            }
            return out;
        }

        @SuppressWarnings("unchecked")
        Arg argument(Map<String, Object> spec, Class<?> type, List<String> used) {
            if (spec.containsKey("concat")) {
                if (!accepts(type, String.class)) return null;
                List<Object> parts = (List<Object>) spec.get("concat");
                Arg[] values = new Arg[parts.size()];
                for (int i = 0; i < values.length; i++) {
                    values[i] = argument((Map<String, Object>) parts.get(i), Object.class, used);
                }
                return facts -> {
                    StringBuilder text = new StringBuilder();
                    for (Arg part : values) text.append(String.valueOf(part.value(facts)));
                    return text.toString();
                };
            }
            String var = (String) spec.get("var");
            if (var == null) {
                Object value = constant(spec, type);
                return value == null ? null : facts -> value;
            }
            Class<?> varType = varTypes.get(var);
            if (varType == null) throw new Reject("variable " + var + " is not bound");
            int at = used.indexOf(var);
            if (at < 0) {
                used.add(var);
                at = used.size() - 1;
            }
            final int index = at;
            String getter = (String) spec.get("getter");
            if (getter == null) return accepts(type, varType) ? facts -> facts[index] : null;
            Method read;
            try {
                read = varType.getMethod(getter);
            } catch (NoSuchMethodException e) {
                throw new Reject("no method " + getter + "() of " + varType.getName());
            }
            if (read.getReturnType() == void.class || Modifier.isStatic(read.getModifiers())) throw new Reject(getter + "() is not a getter");
            return accepts(type, read.getReturnType()) ? facts -> invoke(read, facts[index], NO_ARGS) : null;
        }

        /** Whether a parameter of type {@code param} takes a value of type {@code value} without widening. */
        static boolean accepts(Class<?> param, Class<?> value) {
            if (boxed(param) == boxed(value)) return true;
            return !param.isPrimitive() && param.isAssignableFrom(boxed(value));
        }

        /** A literal as an argument of a parameter of this type, or null if it does not fit exactly. */
        @SuppressWarnings("unchecked")
        static Object constant(Map<String, Object> lit, Class<?> t) {
            if (lit.containsKey("s")) {
                return t == String.class || t == Object.class || t == CharSequence.class ? lit.get("s") : null;
            }
            if (lit.containsKey("b")) {
                return t == boolean.class || t == Boolean.class || t == Object.class ? lit.get("b") : null;
            }
            String digits = (String) lit.get("n");
            boolean decimal = digits.contains(".");
            if ((t == int.class || t == Integer.class) && !decimal) return Integer.valueOf(digits);
            if ((t == long.class || t == Long.class) && !decimal) return Long.valueOf(digits);
            if (t == double.class || t == Double.class) return Double.valueOf(digits);
            if (t == Object.class || t == Number.class) return decimal ? (Object) Double.valueOf(digits) : (Object) Integer.valueOf(digits);
            return null;
        }
    }

    /** The rules of one package that were built here (no declarations: those come from the declarations unit). */
    static final class PlainModel implements Model {
        private final String packageName;
        final List<Rule> rules = new ArrayList<Rule>();

        PlainModel(String packageName) { this.packageName = packageName; }

        public String getName() { return packageName + ".plain"; }
        public String getPackageName() { return packageName; }
        public List<Global> getGlobals() { return Collections.emptyList(); }
        public List<Rule> getRules() { return rules; }
        public List<Query> getQueries() { return Collections.emptyList(); }
        public List<TypeMetaData> getTypeMetaDatas() { return Collections.emptyList(); }
        public List<EntryPoint> getEntryPoints() { return Collections.emptyList(); }
    }
}
