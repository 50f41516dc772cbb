package org.printeps.gateway;

import java.lang.reflect.Array;
import java.lang.reflect.GenericArrayType;
import java.lang.reflect.Method;
import java.lang.reflect.Modifier;
import java.lang.reflect.ParameterizedType;
import java.lang.reflect.Type;
import java.lang.reflect.TypeVariable;
import java.lang.reflect.WildcardType;
import java.util.ArrayList;
import java.util.Arrays;
import java.util.HashMap;
import java.util.List;
import java.util.Map;

import org.printeps.gateway.PlainRules.Reject;

/**
 * The method a then-part call names, chosen as javac chooses it (JLS 15.12.2): among the public
 * methods of that name, those applicable in phase 1 (no boxing, no varargs: identity and widening
 * only), else phase 2 (boxing and unboxing too), else phase 3 (variable arity); of those, the most
 * specific (15.12.2.5). Then it is called as the compiled code would call it: widened, boxed, the
 * variable arguments in an array of the parameter's component type.
 *
 * Why: {@code Math.max($a.getAge(), 1L)} is {@code max(long, long)} because of widening,
 * {@code String.format("%s|%d", $id, n)} is a varargs call; a plain rule must call the very method
 * the compiled rule calls, or it prints another text. Generic methods (their types depend on
 * inference) and ties javac would report as ambiguous are refused: the compiler takes those rules.
 */
final class PlainOverloads {
    private PlainOverloads() {}

    /** A chosen method and how its arguments are passed. */
    static final class Chosen {
        final Method method;
        final Class<?>[] params;
        final boolean varargs;  // chosen in phase 3: the trailing arguments go in one array

        Chosen(Method method, boolean varargs) {
            this.method = PlainValues.direct(method);
            this.params = method.getParameterTypes();
            this.varargs = varargs;
        }

        /** The method's return type: the static type of the call in the expression around it. */
        Class<?> type() { return method.getReturnType(); }

        /** Calls it on {@code target} (ignored for a static method) with the arguments' values. */
        Object call(Object target, Object[] args) throws Exception {
            int fixed = varargs ? params.length - 1 : params.length;
            Object[] values = new Object[params.length];
            for (int i = 0; i < fixed; i++) values[i] = unboxable(args[i], params[i]);
            if (varargs) {
                Class<?> component = params[fixed].getComponentType();
                Object rest = Array.newInstance(component, args.length - fixed);
                for (int i = fixed; i < args.length; i++) Array.set(rest, i - fixed, unboxable(args[i], component));
                values[fixed] = rest;
            }
            return PlainValues.invoke(method, target, values);
        }

        /** A null unboxed by the compiled code throws NullPointerException there: here too. */
        private static Object unboxable(Object value, Class<?> param) {
            if (value == null && param.isPrimitive()) throw new NullPointerException("null passed as a " + param.getName());
            return value;
        }
    }

    /**
     * The method {@code name} of {@code owner} javac calls with arguments of static types
     * {@code args}; {@code statics}: a call on the class itself (an instance method is an error there).
     */
    static Chosen choose(Class<?> owner, String name, boolean statics, Class<?>[] args) {
        List<Method> candidates = candidates(owner, name);
        if (candidates.isEmpty()) throw new Reject("no method " + name + " of " + owner.getName());
        for (int phase = 1; phase <= 3; phase++) {
            List<Method> applicable = new ArrayList<Method>();
            for (Method m : candidates) {
                if (applicable(m, args, phase)) applicable.add(m);
            }
            if (applicable.isEmpty()) continue;
            for (Method m : applicable) {
                if (generic(m)) throw new Reject("the generic method " + m + " (its types are inferred)");
            }
            Method best = mostSpecific(applicable, args.length, phase == 3);
            if (statics && !Modifier.isStatic(best.getModifiers())) throw new Reject(best + " is not static");
            if (!Modifier.isPublic(best.getDeclaringClass().getModifiers())) {
                throw new Reject(best + " is declared in a class reflection may not call it through");
            }
            return new Chosen(best, phase == 3);
        }
        throw new Reject("no method " + name + " of " + owner.getName() + " takes " + Arrays.toString(args));
    }

    /** The public methods of that name, one per signature (no bridges: the override stands). */
    private static List<Method> candidates(Class<?> owner, String name) {
        Map<List<Class<?>>, Method> bySignature = new HashMap<List<Class<?>>, Method>();
        for (Method m : owner.getMethods()) {
            if (!m.getName().equals(name) || m.isBridge() || m.isSynthetic()) continue;
            List<Class<?>> signature = Arrays.asList(m.getParameterTypes());
            Method known = bySignature.get(signature);
            if (known == null || known.getDeclaringClass().isAssignableFrom(m.getDeclaringClass())) bySignature.put(signature, m);
        }
        return new ArrayList<Method>(bySignature.values());
    }

    static boolean applicable(Method m, Class<?>[] args, int phase) {
        Class<?>[] params = m.getParameterTypes();
        if (phase < 3) {
            if (params.length != args.length) return false;
            for (int i = 0; i < args.length; i++) {
                if (!convertible(args[i], params[i], phase == 2)) return false;
            }
            return true;
        }
        if (!m.isVarArgs() || args.length < params.length - 1) return false;
        for (int i = 0; i < args.length; i++) {
            if (!convertible(args[i], parameter(params, i, true), true)) return false;
        }
        return true;
    }

    /** The type the i-th argument is passed as (the component type past a varargs method's last fixed parameter). */
    private static Class<?> parameter(Class<?>[] params, int i, boolean varargs) {
        if (varargs && i >= params.length - 1) return params[params.length - 1].getComponentType();
        return params[i];
    }

    /** Method invocation conversion (JLS 5.3): strict (identity, widening), loose adds boxing and unboxing. */
    static boolean convertible(Class<?> from, Class<?> to, boolean loose) {
        if (from == to) return true;
        if (from.isPrimitive() && to.isPrimitive()) return widens(from, to);
        if (!from.isPrimitive() && !to.isPrimitive()) return to.isAssignableFrom(from);
        if (!loose) return false;
        if (from.isPrimitive()) return to.isAssignableFrom(boxing(from));  // boxing, then a widening reference
        Class<?> unboxed = unboxed(from);  // unboxing, then a widening primitive
        return unboxed != null && (unboxed == to || widens(unboxed, to));
    }

    /** The primitive widening conversions (JLS 5.1.2), which are also primitive subtyping (4.10.1). */
    static boolean widens(Class<?> from, Class<?> to) {
        List<Class<?>> wider;
        if (from == byte.class) wider = Arrays.asList(short.class, int.class, long.class, float.class, double.class);
        else if (from == short.class || from == char.class) wider = Arrays.asList(int.class, long.class, float.class, double.class);
        else if (from == int.class) wider = Arrays.asList(long.class, float.class, double.class);
        else if (from == long.class) wider = Arrays.asList(float.class, double.class);
        else if (from == float.class) wider = Arrays.<Class<?>>asList(double.class);
        else return false;
        return wider.contains(to);
    }

    /** The boxing conversion's class of a primitive type (JLS 5.1.7). */
    static Class<?> boxing(Class<?> t) {
        if (t == int.class) return Integer.class;
        if (t == long.class) return Long.class;
        if (t == double.class) return Double.class;
        if (t == boolean.class) return Boolean.class;
        if (t == char.class) return Character.class;
        if (t == byte.class) return Byte.class;
        if (t == short.class) return Short.class;
        if (t == float.class) return Float.class;
        return Void.class;  // void: boxes into nothing an argument could be
    }

    static Class<?> unboxed(Class<?> t) {
        if (t == Integer.class) return int.class;
        if (t == Long.class) return long.class;
        if (t == Double.class) return double.class;
        if (t == Boolean.class) return boolean.class;
        if (t == Character.class) return char.class;
        if (t == Byte.class) return byte.class;
        if (t == Short.class) return short.class;
        if (t == Float.class) return float.class;
        return null;
    }

    /** S &lt;: T: reference subtyping, or primitive subtyping (the widening order). */
    static boolean subtype(Class<?> s, Class<?> t) {
        if (s == t) return true;
        if (s.isPrimitive() || t.isPrimitive()) return s.isPrimitive() && t.isPrimitive() && widens(s, t);
        return t.isAssignableFrom(s);
    }

    /** The one maximally specific method (JLS 15.12.2.5), or a Reject where javac reports an ambiguity. */
    static Method mostSpecific(List<Method> applicable, int arity, boolean varargs) {
        List<Method> maximal = new ArrayList<Method>();
        for (Method m : applicable) {
            boolean beaten = false;
            for (Method other : applicable) {
                if (other != m && moreSpecific(other, m, arity, varargs) && !moreSpecific(m, other, arity, varargs)) {
                    beaten = true;
                    break;
                }
            }
            if (!beaten) maximal.add(m);
        }
        if (maximal.size() != 1) throw new Reject("ambiguous call: " + maximal);
        return maximal.get(0);
    }

    /** m1 is more specific than m2 for {@code arity} arguments. */
    static boolean moreSpecific(Method m1, Method m2, int arity, boolean varargs) {
        Class<?>[] s = m1.getParameterTypes(), t = m2.getParameterTypes();
        for (int i = 0; i < arity; i++) {
            if (!subtype(parameter(s, i, varargs), parameter(t, i, varargs))) return false;
        }
        if (varargs && t.length == arity + 1) {  // m2's variable arity parameter no argument reached
            return subtype(parameter(s, arity, true), parameter(t, arity, true));
        }
        return true;
    }

    /** Whether the method's types depend on type variables (its own or its class's): inference, not here. */
    static boolean generic(Method m) {
        if (m.getTypeParameters().length > 0 || mentionsVariable(m.getGenericReturnType())) return true;
        for (Type t : m.getGenericParameterTypes()) {
            if (mentionsVariable(t)) return true;
        }
        return false;
    }

    private static boolean mentionsVariable(Type t) {
        if (t instanceof TypeVariable) return true;
        if (t instanceof GenericArrayType) return mentionsVariable(((GenericArrayType) t).getGenericComponentType());
        if (t instanceof ParameterizedType) {
            for (Type a : ((ParameterizedType) t).getActualTypeArguments()) {
                if (mentionsVariable(a)) return true;
            }
        }
        if (t instanceof WildcardType) {
            for (Type b : ((WildcardType) t).getUpperBounds()) {
                if (mentionsVariable(b)) return true;
            }
            for (Type b : ((WildcardType) t).getLowerBounds()) {
                if (mentionsVariable(b)) return true;
            }
        }
        return false;
    }
}
