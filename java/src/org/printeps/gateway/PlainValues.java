package org.printeps.gateway;

import java.lang.invoke.MethodHandles;
import java.lang.invoke.MethodType;
import java.lang.reflect.InvocationTargetException;
import java.lang.reflect.Method;
import java.lang.reflect.Modifier;
import java.util.Map;
import java.util.function.Function;

import org.drools.model.DomainClassMetadata;
import org.drools.model.Index;
import org.drools.model.functions.Function1;
import org.objectweb.asm.ClassWriter;
import org.objectweb.asm.MethodVisitor;
import org.objectweb.asm.Opcodes;
import org.objectweb.asm.Type;

import org.printeps.gateway.PlainRules.Reject;

/**
 * The values plain rules read and compare ({@link PlainRules}): a fact's fields, literals typed as
 * the executable model types them, constraint ids, and comparisons that are null-safe as its
 * generated code. Why apart: every part of a plain rule (patterns, accumulates, then-parts) reads
 * values the same way; one place keeps them identical to what the compiler would generate.
 */
final class PlainValues {
    private PlainValues() {}

    /** A readable field of a fact class: its getter, type and property index. */
    static final class Property implements Function1<Object, Object> {
        final String name;
        final Method getter;
        final Class<?> type;  // as declared (a primitive stays primitive)
        final int index;
        private final Function<Object, Object> read;

        private Property(String name, Method getter, int index) {
            this.name = name;
            this.getter = direct(getter);
            this.type = getter.getReturnType();
            this.index = index;
            this.read = reader(getter);
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
            return read.apply(fact);
        }

        /**
         * Equal when they read one getter of one class, whichever build made them. Why: Drools
         * shares a join, {@code not}, {@code exists} or accumulate node only when its constraints'
         * declarations are equal, and a declaration compares the function that reads its field.
         * Each plain unit makes its own {@code Property} objects, so with identity two units never
         * shared such a node where one build of the whole DRL shares it (a rule base of more than one
         * unit, or after a one-rule edit): more nodes, and rules whose matches fired in another
         * order, since a rule's place among the rules sharing a node decides that order.
         */
        @Override
        public boolean equals(Object other) {
            if (this == other) return true;
            if (!(other instanceof Property)) return false;
            Property that = (Property) other;
            return index == that.index && name.equals(that.name) && getter.equals(that.getter);
        }

        @Override
        public int hashCode() {
            return 31 * getter.hashCode() + name.hashCode();
        }
    }

    // ------------------------------------------------------------------ reading a getter

    /**
     * A getter as a generated function that calls it directly, as the executable model's generated
     * lambdas do ({@code _this.getAge()}); by reflection only where no such function can be made
     * (a getter of a JDK class, see {@link #generated}). Why: reflective calls are not inlined, and
     * at 10,000 business rules the plain rules' getters called through {@code Method.invoke} were
     * 14% of a request's CPU (JFR, 2026-11-27: alpha constraints such as {@code region in (…)} and
     * {@code amount > …} read a field of every fact that reaches them). Either way a getter's
     * exception reaches the caller as it did: unchecked ones as they are, checked ones wrapped in a
     * RuntimeException.
     */
    static Function<Object, Object> reader(Method getter) {
        Function<Object, Object> direct = generated(getter);
        if (direct != null) return fact -> call(direct, fact);
        Method reflective = direct(getter);
        return fact -> {
            try {
                return reflective.invoke(fact);
            } catch (InvocationTargetException e) {
                throw rethrow(e.getCause());
            } catch (IllegalAccessException e) {
                throw new IllegalStateException(e);
            }
        };
    }

    /** Whether {@link #reader} calls {@code getter} directly (false: by reflection). */
    static boolean readsDirectly(Method getter) {
        return generated(getter) != null;
    }

    private static Object call(Function<Object, Object> direct, Object fact) {
        try {
            return direct.apply(fact);
        } catch (RuntimeException | Error e) {
            throw e;
        } catch (Throwable checked) {  // a getter declaring a checked exception: as Method.invoke's cause
            throw rethrow(checked);
        }
    }

    /**
     * A {@code Function} whose {@code apply} calls the public, non-static, no-argument
     * {@code getter} of a public class (boxing a primitive), or null where none can be made: a
     * class of the JDK's own modules, which are not open to this one.
     *
     * How: a small class written with ASM (from the same wheel as Drools) and defined next to the
     * getter's class, in its package and class loader (a private lookup in it), so it sees the
     * declared types of the rule base's loader and goes away with them. One per getter, kept with
     * its class. ({@code LambdaMetafactory} would do, but it refuses a lookup that crosses from the
     * helpers' module into the rule base loader's.)
     */
    static Function<Object, Object> generated(Method getter) {
        Class<?> owner = getter.getDeclaringClass();
        if (getter.getParameterCount() != 0 || Modifier.isStatic(getter.getModifiers())
                || !Modifier.isPublic(getter.getModifiers()) || !Modifier.isPublic(owner.getModifiers())
                || owner.getClassLoader() == null || owner.isHidden() || owner.isArray()) {
            return null;
        }
        try {
            return READERS.get(owner).computeIfAbsent(getter.getName() + Type.getMethodDescriptor(getter), k -> define(owner, getter));
        } catch (RuntimeException | LinkageError refused) {  // IllegalAccess, a class the loader refuses
            return null;
        }
    }

    /** The readers made for each class (see {@link #generated}). */
    private static final ClassValue<java.util.concurrent.ConcurrentHashMap<String, Function<Object, Object>>> READERS =
            new ClassValue<java.util.concurrent.ConcurrentHashMap<String, Function<Object, Object>>>() {
                @Override
                protected java.util.concurrent.ConcurrentHashMap<String, Function<Object, Object>> computeValue(Class<?> type) {
                    return new java.util.concurrent.ConcurrentHashMap<String, Function<Object, Object>>();
                }
            };

    @SuppressWarnings("unchecked")
    private static Function<Object, Object> define(Class<?> owner, Method getter) {
        try {
            MethodHandles.Lookup lookup = MethodHandles.privateLookupIn(owner, MethodHandles.lookup());
            String ownerName = Type.getInternalName(owner);
            String name = ownerName + "$$PrintepsRead$" + getter.getName();
            Class<?> reader;
            try {
                reader = lookup.defineClass(readerBytes(name, ownerName, owner.isInterface(), getter));
            } catch (LinkageError defined) {  // made by another build of the same class meanwhile
                reader = lookup.findClass(name.replace('/', '.'));
            }
            return (Function<Object, Object>) reader.getConstructor().newInstance();
        } catch (ReflectiveOperationException e) {
            throw new IllegalStateException(e);
        }
    }

    /** {@code public final class name implements Function { Object apply(Object o) { return box(((Owner) o).getter()); } }} */
    private static byte[] readerBytes(String name, String ownerName, boolean ownerIsInterface, Method getter) {
        ClassWriter cw = new ClassWriter(ClassWriter.COMPUTE_MAXS);
        cw.visit(Opcodes.V1_8, Opcodes.ACC_PUBLIC | Opcodes.ACC_FINAL | Opcodes.ACC_SYNTHETIC, name, null,
                 "java/lang/Object", new String[] {"java/util/function/Function"});
        MethodVisitor init = cw.visitMethod(Opcodes.ACC_PUBLIC, "<init>", "()V", null, null);
        init.visitCode();
        init.visitVarInsn(Opcodes.ALOAD, 0);
        init.visitMethodInsn(Opcodes.INVOKESPECIAL, "java/lang/Object", "<init>", "()V", false);
        init.visitInsn(Opcodes.RETURN);
        init.visitMaxs(0, 0);
        init.visitEnd();
        MethodVisitor apply = cw.visitMethod(Opcodes.ACC_PUBLIC, "apply", "(Ljava/lang/Object;)Ljava/lang/Object;", null, null);
        apply.visitCode();
        apply.visitVarInsn(Opcodes.ALOAD, 1);
        apply.visitTypeInsn(Opcodes.CHECKCAST, ownerName);
        apply.visitMethodInsn(ownerIsInterface ? Opcodes.INVOKEINTERFACE : Opcodes.INVOKEVIRTUAL, ownerName, getter.getName(),
                              Type.getMethodDescriptor(getter), ownerIsInterface);
        Class<?> result = getter.getReturnType();
        if (result.isPrimitive()) {
            String box = Type.getInternalName(MethodType.methodType(result).wrap().returnType());
            apply.visitMethodInsn(Opcodes.INVOKESTATIC, box, "valueOf", "(" + Type.getDescriptor(result) + ")L" + box + ";", false);
        }
        apply.visitInsn(Opcodes.ARETURN);
        apply.visitMaxs(0, 0);
        apply.visitEnd();
        cw.visitEnd();
        return cw.toByteArray();
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

    static final Object[] NO_ARGS = new Object[0];

    /** The right side of a beta index on a bound field: the variable's value itself. */
    static final Function1<Object, Object> IDENTITY = v -> v;

    /**
     * The method with Java's access check turned off for calls through it ({@code setAccessible}),
     * or as it is where the module system refuses. Why: every {@code Method.invoke} of a plain
     * rule's getter or then-part call otherwise re-checks access (3% of a 1,000-rule business
     * request's CPU in a JFR profile, 2026-11-27); the methods are public ones found by
     * {@code getMethod}, so nothing becomes callable that was not.
     */
    static Method direct(Method method) {
        try {
            method.setAccessible(true);
        } catch (RuntimeException refused) {  // InaccessibleObjectException, SecurityException: keep checking
        }
        return method;
    }

    static Object invoke(Method method, Object target, Object[] values) throws Exception {
        try {
            return method.invoke(target, values);
        } catch (InvocationTargetException e) {
            Throwable cause = e.getCause();
            if (cause instanceof Exception) throw (Exception) cause;
            throw rethrow(cause);
        }
    }
}
