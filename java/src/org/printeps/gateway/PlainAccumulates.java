package org.printeps.gateway;

import java.util.ArrayList;
import java.util.List;
import java.util.Map;

import org.drools.model.DSL;
import org.drools.model.Declaration;
import org.drools.model.Index;
import org.drools.model.PatternDSL;
import org.drools.model.RuleItemBuilder;
import org.drools.model.Variable;
import org.drools.model.functions.Function1;
import org.drools.model.functions.Predicate1;

import org.printeps.gateway.PlainRules.Reject;

import static org.printeps.gateway.PlainValues.*;

/**
 * The accumulates of a plain rule ({@link PlainRule}): {@code accumulate( …; $t : sum( $a ); $t > 1 )}
 * and {@code Number( … ) from accumulate( …, count( 1 ) | sum | min | max( $v ) )}, with the
 * accumulate functions and result types the executable model chooses. What an accumulate binds
 * inside is not visible after it; its result variable is, with a static type the generated code
 * may declare otherwise (so a then-part only prints it: {@link PlainRule#uncertain}).
 */
final class PlainAccumulates {
    private final PlainRule rule;

    PlainAccumulates(PlainRule rule) { this.rule = rule; }

    @SuppressWarnings({"unchecked", "rawtypes"})
    void accumulate(Map<String, Object> a, List<RuleItemBuilder<?>> items) {
        if (rule.fromRequest) {
            requestAccumulate(a, items);
            return;
        }
        List<Object> binds = new ArrayList<Object>();
        PatternDSL.PatternDef<Object> source = rule.pattern((Map<String, Object>) a.get("source"), binds);
        String sourceVar = source.getFirstVariable().getName();
        Class<?> type = rule.varTypes.remove(sourceVar);  // bound inside the accumulate: not visible after it
        rule.vars.remove(sourceVar);
        String function = (String) a.get("function");
        String arg = (String) a.get("arg");
        Variable<Object> input = null;
        for (Object b : binds) {
            Map<String, Object> bind = (Map<String, Object>) b;
            Property field = rule.context.property(type, (String) bind.get("field"));
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
        if (rule.vars.containsKey(resultName)) throw new Reject("variable " + resultName + " bound twice");
        Declaration<Object> result = (Declaration<Object>) (Declaration) DSL.declarationOf(resultType, rule.context.metadata(resultType), resultName);
        bindResult(resultName, result, resultType);
        items.add((RuleItemBuilder<?>) DSL.accumulate(source, fn.as(result)));
        List<Object> tests = (List<Object>) a.get("constraints");
        if (!tests.isEmpty()) items.add(sumTests(PatternDSL.pattern(result), resultType, tests));
    }

    /** The tests of a sum bound to a variable ({@code $t > 1}): decimal comparisons with numbers. */
    @SuppressWarnings("unchecked")
    private static PatternDSL.PatternDef<Object> sumTests(PatternDSL.PatternDef<Object> on, Class<?> resultType, List<Object> tests) {
        for (Object t : tests) {
            Map<String, Object> c = (Map<String, Object>) t;
            Object value = literal(c.get("literal"), double.class);
            Index.ConstraintType op = constraintType((String) c.get("op"));
            Predicate1<Object> test = total -> compare(Kind.DECIMAL, op, total, value);
            on = on.expr("PLAIN:" + resultType.getName() + ":" + c.get("text"), test);
        }
        return on;
    }

    /** An accumulate's result variable, visible after it, with a static type the generated code may declare otherwise. */
    private void bindResult(String name, Declaration<Object> result, Class<?> resultType) {
        rule.vars.put(name, result);
        rule.varTypes.put(name, resultType);
        rule.uncertain.add(name);
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
        if (rule.fromRequest) {
            requestFromAccumulate(a, resultSpec, items);
            return;
        }
        java.util.Set<String> before = new java.util.HashSet<String>(rule.vars.keySet());
        List<Object> binds = new ArrayList<Object>();
        PatternDSL.PatternDef<Object> source = rule.pattern((Map<String, Object>) a.get("source"), binds);
        Class<?> type = rule.varTypes.get(source.getFirstVariable().getName());
        rule.vars.keySet().retainAll(before);  // bound inside the accumulate: not visible after it
        rule.varTypes.keySet().retainAll(before);
        String function = (String) a.get("function");
        Map<String, Object> arg = (Map<String, Object>) a.get("arg");
        String argVar = (String) arg.get("var");
        Variable<Object> input = null;
        Class<?> inputType = Integer.class;
        for (Object b : binds) {
            Map<String, Object> bind = (Map<String, Object>) b;
            Property field = rule.context.property(type, (String) bind.get("field"));
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
        String resultName = resultVar != null ? resultVar : "$pattern_Number$" + (++rule.unnamed) + "$";
        if (rule.vars.containsKey(resultName)) throw new Reject("variable " + resultName + " bound twice");
        Declaration<Object> result = (Declaration<Object>) (Declaration) DSL.declarationOf(resultType, rule.context.metadata(resultType), resultName);
        items.add((RuleItemBuilder<?>) DSL.accumulate(source, DSL.accFunction(fn, argument).as(result)));
        bindResult(resultName, result, resultType);
        List<Object> tests = (List<Object>) resultSpec.get("constraints");
        if (tests.isEmpty()) return;
        items.add(numberTests(PatternDSL.pattern(result), resultType, tests));
    }

    /** The result pattern's comparisons of {@code intValue}/{@code longValue}/{@code doubleValue} with numbers. */
    @SuppressWarnings("unchecked")
    private PatternDSL.PatternDef<Object> numberTests(PatternDSL.PatternDef<Object> on, Class<?> resultType, List<Object> tests) {
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
        return on;
    }

    // ---- in a request-join build (PlainRequestJoins): the accumulate read from the request's facts

    /** The field a binding of the source pattern ({@code $m : amount}) reads, or null. */
    @SuppressWarnings("unchecked")
    private static String boundField(Map<String, Object> source, String var) {
        for (Object b : (List<Object>) source.get("binds")) {
            Map<String, Object> bind = (Map<String, Object>) b;
            if (bind.get("var").equals(var)) return (String) bind.get("field");
        }
        return null;
    }

    private Class<?> inputType(Map<String, Object> source, String field) {
        return field == null ? Integer.class : boxed(rule.context.property(rule.resolve((String) source.get("type")), field).type);
    }

    /** {@link #fromAccumulate} with the accumulate read from the request: the same function and result type. */
    @SuppressWarnings("unchecked")
    private void requestFromAccumulate(Map<String, Object> a, Map<String, Object> resultSpec, List<RuleItemBuilder<?>> items) {
        Map<String, Object> source = (Map<String, Object>) a.get("source");
        String function = (String) a.get("function");
        Map<String, Object> arg = (Map<String, Object>) a.get("arg");
        String argVar = (String) arg.get("var");
        String field = argVar == null ? null : boundField(source, argVar);
        if (argVar != null && field == null) throw new Reject("an accumulate over " + argVar + ", not bound in its pattern");
        if (argVar == null && !function.equals("count")) throw new Reject(function + " of a constant");
        Object constant = argVar == null ? literal(arg, int.class) : null;
        java.util.function.Supplier<?> fn = DroolsInternals.accumulateFunction(function, inputType(source, field));
        if (fn == null) throw new Reject("accumulate function " + function + " is left to the compiler");
        Class<?> resultType = DroolsInternals.accumulateResultType(function);
        String resultVar = (String) resultSpec.get("var");
        String resultName = resultVar != null ? resultVar : "$pattern_Number$" + (++rule.unnamed) + "$";
        if (rule.vars.containsKey(resultName)) throw new Reject("variable " + resultName + " bound twice");
        Declaration<Object> result = PlainRequestJoins.accumulate(rule, source, resultName, resultType, function, fn, field, constant);
        items.add(numberTests(PatternDSL.pattern(result), resultType, (List<Object>) resultSpec.get("constraints")));
        items.add(PlainRequestJoins.keepOrder(rule));
        bindResult(resultName, result, resultType);
    }

    /** {@link #accumulate} (a sum bound to a variable, with its tests) read from the request. */
    @SuppressWarnings("unchecked")
    private void requestAccumulate(Map<String, Object> a, List<RuleItemBuilder<?>> items) {
        Map<String, Object> source = (Map<String, Object>) a.get("source");
        String function = (String) a.get("function");
        String argVar = (String) a.get("arg");
        List<Object> binds = (List<Object>) source.get("binds");
        String field = argVar == null ? null : boundField(source, argVar);
        if (!function.equals("sum") || field == null || binds.size() != 1 || inputType(source, field) != Double.class) {
            throw new Reject("accumulate function " + function + " is left to the compiler");
        }
        String resultName = (String) a.get("var");
        if (rule.vars.containsKey(resultName)) throw new Reject("variable " + resultName + " bound twice");
        Class<?> resultType = Double.class;
        Declaration<Object> result = PlainRequestJoins.accumulate(rule, source, resultName, resultType, "sum",
                DroolsInternals.accumulateFunction("sum", Double.class), field, null);
        items.add(sumTests(PatternDSL.pattern(result), resultType, (List<Object>) a.get("constraints")));
        items.add(PlainRequestJoins.keepOrder(rule));
        bindResult(resultName, result, resultType);
    }
}
