package org.printeps.gateway;

import java.lang.reflect.Method;
import java.lang.reflect.Modifier;
import java.util.ArrayList;
import java.util.List;
import java.util.Map;

import org.drools.model.DSL;
import org.drools.model.Global;
import org.drools.model.RuleItemBuilder;
import org.drools.model.Variable;
import org.drools.model.functions.Block0;
import org.drools.model.functions.Block1;
import org.drools.model.functions.Block2;
import org.drools.model.functions.Block3;
import org.drools.model.functions.Block4;

import org.printeps.gateway.PlainRules.Reject;

/**
 * The then-part of a plain rule ({@link PlainRule}): calls on one global whose arguments are
 * literals ({@code 1}, {@code 1L}, {@code 2.5}, text, booleans), bound variables, their getters,
 * text joined with {@code +}, and static calls of {@code java.lang} classes the rule policy allows
 * ({@code String.format}, {@code Math.max}). Each expression has the static type javac gives it,
 * and each call is resolved from those types as javac resolves it ({@link PlainOverloads}): the
 * plain rule calls the very methods the compiled one calls, with the same conversions.
 */
final class PlainThen {
    private final PlainRule rule;
    private final List<String> used = new ArrayList<String>();  // the variables the expressions read, in order

    PlainThen(PlainRule rule) { this.rule = rule; }

    /** An expression of a then-part: its static type and its value when the rule fires. */
    static final class Expr {
        final Class<?> type;
        final Value value;

        Expr(Class<?> type, Value value) {
            this.type = type;
            this.value = value;
        }
    }

    /** The value of an expression from the facts of the variables the then-part reads. */
    interface Value {
        Object of(Object[] facts) throws Exception;
    }

    /** A then-part: calls on one global, with the facts of the variables its arguments read. */
    static final class Calls {
        final PlainOverloads.Chosen[] methods;
        final Value[][] args;

        Calls(PlainOverloads.Chosen[] methods, Value[][] args) {
            this.methods = methods;
            this.args = args;
        }

        void run(Object target, Object... facts) throws Exception {
            for (int k = 0; k < methods.length; k++) methods[k].call(target, values(args[k], facts));
        }
    }

    static Object[] values(Value[] args, Object[] facts) throws Exception {
        Object[] values = new Object[args.length];
        for (int i = 0; i < values.length; i++) values[i] = args[i].of(facts);
        return values;
    }

    @SuppressWarnings({"unchecked", "rawtypes"})
    RuleItemBuilder<?> consequence(List<Object> calls) {
        if (calls.isEmpty()) return DSL.execute((Block0) () -> {});
        String target = null;
        PlainOverloads.Chosen[] methods = new PlainOverloads.Chosen[calls.size()];
        Value[][] args = new Value[calls.size()][];
        for (int k = 0; k < calls.size(); k++) {
            Map<String, Object> call = (Map<String, Object>) calls.get(k);
            String t = (String) call.get("target");
            if (target != null && !target.equals(t)) throw new Reject("calls on more than one global");
            target = t;
            Global<?> global = rule.context.globals.get(rule.pkg + "\0" + t);
            if (global == null) throw new Reject("no global " + t + " in package " + rule.pkg);
            Expr[] given = arguments((List<Object>) call.get("args"));
            methods[k] = PlainOverloads.choose(global.getType(), (String) call.get("method"), false, types(given));
            args[k] = values(given);
        }
        Global<Object> global = (Global<Object>) rule.context.globals.get(rule.pkg + "\0" + target);
        Calls block = new Calls(methods, args);
        Variable[] v = new Variable[used.size()];
        for (int i = 0; i < v.length; i++) v[i] = rule.vars.get(used.get(i));
        switch (v.length) {
            case 0: return DSL.on(global).execute((Block1<Object>) g -> block.run(g));
            case 1: return DSL.on(global, v[0]).execute((Block2<Object, Object>) (g, a) -> block.run(g, a));
            case 2: return DSL.on(global, v[0], v[1]).execute((Block3<Object, Object, Object>) (g, a, b) -> block.run(g, a, b));
            case 3: return DSL.on(global, v[0], v[1], v[2]).execute(
                    (Block4<Object, Object, Object, Object>) (g, a, b, c) -> block.run(g, a, b, c));
            default: throw new Reject("a then-part reading more than three variables");
        }
    }

    /** The arguments of a call. An accumulate result is not one: the generated code may declare
     *  it of another type than its value's (a Number), and the type decides the method. */
    @SuppressWarnings("unchecked")
    Expr[] arguments(List<Object> specs) {
        Expr[] out = new Expr[specs.size()];
        for (int i = 0; i < out.length; i++) {
            Map<String, Object> spec = (Map<String, Object>) specs.get(i);
            if (spec.containsKey("var") && !spec.containsKey("getter") && rule.uncertain.contains(spec.get("var"))) {
                throw new Reject("an accumulate result passed to a method");
            }
            out[i] = expression(spec);
        }
        return out;
    }

    static Class<?>[] types(Expr[] exprs) {
        Class<?>[] out = new Class<?>[exprs.length];
        for (int i = 0; i < out.length; i++) out[i] = exprs[i].type;
        return out;
    }

    static Value[] values(Expr[] exprs) {
        Value[] out = new Value[exprs.length];
        for (int i = 0; i < out.length; i++) out[i] = exprs[i].value;
        return out;
    }

    /** One expression of the description, typed as javac types it. */
    @SuppressWarnings("unchecked")
    Expr expression(Map<String, Object> spec) {
        if (spec.containsKey("concat")) return concat((List<Object>) spec.get("concat"));
        if (spec.containsKey("static")) return staticCall(spec);
        if (spec.containsKey("var")) return variable((String) spec.get("var"), (String) spec.get("getter"));
        return constant(spec);
    }

    /** {@code "text " + $x + …}: every part appended as Java's string concatenation appends it. */
    @SuppressWarnings("unchecked")
    Expr concat(List<Object> parts) {
        Value[] values = new Value[parts.size()];
        for (int i = 0; i < values.length; i++) values[i] = expression((Map<String, Object>) parts.get(i)).value;
        return new Expr(String.class, facts -> {
            StringBuilder text = new StringBuilder();
            for (Value part : values) text.append(String.valueOf(part.of(facts)));
            return text.toString();
        });
    }

    /** {@code Math.max( … )}: a static method of the java.lang class the name means there. */
    @SuppressWarnings("unchecked")
    Expr staticCall(Map<String, Object> spec) {
        Class<?> owner = rule.javaLang((String) spec.get("static"));
        Expr[] given = arguments((List<Object>) spec.get("args"));
        PlainOverloads.Chosen method = PlainOverloads.choose(owner, (String) spec.get("method"), true, types(given));
        if (method.type() == void.class) throw new Reject(method.method + " returns nothing");
        Value[] args = values(given);
        return new Expr(method.type(), facts -> method.call(null, values(args, facts)));
    }

    /** {@code $v} (a fact, a bound field of its boxed type, an accumulate result) or {@code $v.getX()}. */
    Expr variable(String var, String getter) {
        Class<?> varType = rule.varTypes.get(var);
        if (varType == null) throw new Reject("variable " + var + " is not bound");
        int at = used.indexOf(var);
        if (at < 0) {
            used.add(var);
            at = used.size() - 1;
        }
        final int index = at;
        if (getter == null) return new Expr(varType, facts -> facts[index]);
        if (rule.uncertain.contains(var)) throw new Reject("a getter of an accumulate result");
        Method read;
        try {
            read = varType.getMethod(getter);
        } catch (NoSuchMethodException e) {
            throw new Reject("no method " + getter + "() of " + varType.getName());
        }
        if (read.getReturnType() == void.class || Modifier.isStatic(read.getModifiers())) throw new Reject(getter + "() is not a getter");
        if (PlainOverloads.generic(read)) throw new Reject(getter + "() has a generic type");
        // called directly where it can be (PlainValues.generated: a checked exception escapes as
        // itself, as it does from PlainValues.invoke), else by reflection
        final java.util.function.Function<Object, Object> generated = PlainValues.generated(read);
        if (generated != null) return new Expr(read.getReturnType(), facts -> generated.apply(facts[index]));
        final Method direct = PlainValues.direct(read);
        return new Expr(read.getReturnType(), facts -> PlainValues.invoke(direct, facts[index], PlainValues.NO_ARGS));
    }

    /** A literal with its Java type: text, boolean, int, long ({@code 1L}) or double ({@code 2.5}). */
    static Expr constant(Map<String, Object> lit) {
        if (lit.containsKey("s")) {
            Object text = lit.get("s");
            return new Expr(String.class, facts -> text);
        }
        if (lit.containsKey("b")) {
            Object flag = lit.get("b");
            return new Expr(boolean.class, facts -> flag);
        }
        if (lit.containsKey("l")) {
            Long number = Long.valueOf((String) lit.get("l"));  // out of range: NumberFormatException, the compiler's
            return new Expr(long.class, facts -> number);
        }
        String digits = (String) lit.get("n");
        if (digits == null) throw new Reject("unknown literal " + lit);
        if (digits.contains(".")) {
            Double number = Double.valueOf(digits);
            return new Expr(double.class, facts -> number);
        }
        Integer number = Integer.valueOf(digits);
        return new Expr(int.class, facts -> number);
    }
}
