package org.printeps.gateway;

import java.lang.reflect.Method;
import java.util.ArrayList;
import java.util.HashMap;
import java.util.LinkedHashMap;
import java.util.List;
import java.util.Map;

import org.kie.api.KieBase;
import org.kie.api.definition.KiePackage;
import org.kie.api.definition.type.FactField;
import org.kie.api.definition.type.FactType;

/**
 * The declared types ({@code declare Customer ... end}) of one compiled rule set, and the strict
 * conversion between JSON-like maps and their instances.
 *
 * Why strict: a fact with a misspelt field or a string where an int is declared must be refused
 * with an error naming the fact and field, before anything fires, not silently defaulted.
 */
public final class TypeRegistry {

    /** One field of a declared type, with cached accessors. */
    static final class FieldInfo {
        final String name;
        final Class<?> type;
        final Method getter;
        final Method setter;
        /** The getter as a direct call ({@link PlainValues#reader}), made at its first read. */
        private volatile java.util.function.Function<Object, Object> read;
        FieldInfo(String name, Class<?> type, Method getter, Method setter) {
            this.name = name; this.type = type; this.getter = getter; this.setter = setter;
        }

        /** The field's value in {@code fact} (null if its getter throws). Why not {@code Method.invoke}:
         *  every fired match and every returned fact is written through here, and a reflective call is
         *  not inlined (the same reason plain rules read through these readers). */
        Object value(Object fact) {
            java.util.function.Function<Object, Object> r = read;
            if (r == null) read = r = PlainValues.reader(getter);  // a race makes the same cached reader twice
            try {
                return r.apply(fact);
            } catch (Exception e) {  // as before: a getter that throws reads as null
                return null;
            }
        }
    }

    /** One declared type. */
    static final class TypeInfo {
        final String simpleName;
        final String fullName;
        final Class<?> cls;
        final Map<String, FieldInfo> fields = new LinkedHashMap<String, FieldInfo>();
        final boolean event;
        /** The public no-argument constructor, looked up once (null: none, reported at build). */
        final java.lang.reflect.Constructor<?> constructor;
        TypeInfo(String simpleName, String fullName, Class<?> cls, boolean event) {
            this.simpleName = simpleName; this.fullName = fullName; this.cls = cls; this.event = event;
            java.lang.reflect.Constructor<?> c;
            try { c = cls.getConstructor(); } catch (Exception e) { c = null; }
            this.constructor = c;
        }
    }

    /** A refused fact field: which fact (index, type, id), which field, why. */
    public static final class FactProblem extends Exception {
        final String field;
        FactProblem(String field, String message) { super(message); this.field = field; }
    }

    private final Map<String, TypeInfo> byName = new HashMap<String, TypeInfo>();
    private final Map<Class<?>, TypeInfo> byClass = new HashMap<Class<?>, TypeInfo>();
    private final List<TypeInfo> ordered = new ArrayList<TypeInfo>();

    public TypeRegistry(KieBase kieBase) {
        for (KiePackage pkg : kieBase.getKiePackages()) {
            for (FactType ft : pkg.getFactTypes()) add(ft);
        }
    }

    private void add(FactType ft) {
        Class<?> cls = ft.getFactClass();
        boolean event = isEvent(cls);
        TypeInfo t = new TypeInfo(ft.getSimpleName(), ft.getName(), cls, event);
        List<FactField> fieldList = new ArrayList<FactField>(ft.getFields());
        final List<String> declared = new ArrayList<String>();
        for (java.lang.reflect.Field df : cls.getDeclaredFields()) declared.add(df.getName());
        java.util.Collections.sort(fieldList, new java.util.Comparator<FactField>() {
            public int compare(FactField a, FactField b) {
                return Integer.compare(rank(declared, a.getName()), rank(declared, b.getName()));
            }
        });
        for (FactField f : fieldList) {
            String cap = Character.toUpperCase(f.getName().charAt(0)) + f.getName().substring(1);
            Method getter = find(cls, (f.getType() == boolean.class ? "is" : "get") + cap);
            if (getter == null) getter = find(cls, "get" + cap);
            Method setter = find(cls, "set" + cap, f.getType());
            t.fields.put(f.getName(), new FieldInfo(f.getName(), f.getType(), getter, setter));
        }
        if (!byName.containsKey(t.simpleName)) byName.put(t.simpleName, t);
        byName.put(t.fullName, t);
        byClass.put(cls, t);
        ordered.add(t);
    }

    private static int rank(List<String> declared, String name) {
        int i = declared.indexOf(name);
        return i < 0 ? Integer.MAX_VALUE : i;
    }

    private static boolean isEvent(Class<?> cls) {
        for (java.lang.annotation.Annotation a : cls.getAnnotations()) {
            String n = a.annotationType().getName();
            if (n.endsWith(".Role")) {
                return a.toString().contains("EVENT") || a.toString().contains("Event");
            }
        }
        return false;
    }

    private static Method find(Class<?> cls, String name, Class<?>... params) {
        try { return cls.getMethod(name, params); } catch (NoSuchMethodException e) { return null; }
    }

    /** {"Customer": {"id": "String", "age": "int"}, ...} as JSON, for documentation and the workbench. */
    public String describe() {
        Map<String, Object> out = new LinkedHashMap<String, Object>();
        for (TypeInfo t : ordered) {
            Map<String, Object> fields = new LinkedHashMap<String, Object>();
            for (FieldInfo f : t.fields.values()) fields.put(f.name, typeName(f.type));
            out.put(out.containsKey(t.simpleName) ? t.fullName : t.simpleName, fields);
        }
        return Json.toJson(out);
    }

    /** {"Customer": "org.printeps.reception.Customer", ...} */
    public String fullNames() {
        Map<String, Object> out = new LinkedHashMap<String, Object>();
        for (TypeInfo t : ordered) out.put(t.simpleName, t.fullName);
        return Json.toJson(out);
    }

    static String typeName(Class<?> c) {
        if (c.isPrimitive()) return c.getName();
        if (c.getName().startsWith("java.lang.")) return c.getSimpleName();
        return c.getName();
    }

    TypeInfo type(String name) { return byName.get(name); }

    /** Whether any declared type is an event (@role(event)). */
    boolean hasEventTypes() {
        for (TypeInfo t : ordered) if (t.event) return true;
        return false;
    }

    boolean isEvent(Object fact) {
        TypeInfo t = byClass.get(fact.getClass());
        return t != null && t.event;
    }

    String knownTypes() {
        StringBuilder b = new StringBuilder();
        for (TypeInfo t : ordered) { if (b.length() > 0) b.append(", "); b.append(t.simpleName); }
        return b.length() == 0 ? "(none declared)" : b.toString();
    }

    /** Builds an instance of {@code t} from {@code values} (the "type" key is ignored). */
    Object build(TypeInfo t, Map<?, ?> values, int depth) throws FactProblem {
        Object obj;
        try {
            if (t.constructor == null) obj = t.cls.getConstructor().newInstance();  // throws the usual error
            else obj = t.constructor.newInstance();
        } catch (Exception e) {
            throw new FactProblem(null, "cannot create a " + t.simpleName + ": " + e);
        }
        for (Map.Entry<?, ?> e : values.entrySet()) {
            String key = String.valueOf(e.getKey());
            if (key.equals("type")) continue;
            FieldInfo f = t.fields.get(key);
            if (f == null) {
                throw new FactProblem(key, "unknown field '" + key + "' for type " + t.simpleName
                        + " (fields: " + String.join(", ", t.fields.keySet()) + ")");
            }
            Object v = convert(f, e.getValue(), depth);
            if (f.setter == null) throw new FactProblem(key, "field '" + key + "' cannot be set");
            try {
                f.setter.invoke(obj, v);
            } catch (Exception ex) {
                throw new FactProblem(key, "cannot set field '" + key + "': " + ex);
            }
        }
        return obj;
    }

    /** Converts a JSON value to {@code type} with the same strict rules as fact fields (for globals). */
    Object convertValue(String name, Class<?> type, Object v) throws FactProblem {
        return convert(new FieldInfo(name, type, null, null), v, 0);
    }

    /** A declared type's class by simple or full name, or null. */
    Class<?> declaredClass(String name) {
        TypeInfo t = byName.get(name);
        return t == null ? null : t.cls;
    }

    private Object convert(FieldInfo f, Object v, int depth) throws FactProblem {
        Class<?> t = f.type;
        String where = "field '" + f.name + "'";
        if (v == null) {
            if (t.isPrimitive()) throw new FactProblem(f.name, where + ": null is not allowed, " + typeName(t) + " expected");
            return null;
        }
        if (t == int.class || t == Integer.class) return (int) integral(f, v, Integer.MIN_VALUE, Integer.MAX_VALUE);
        if (t == long.class || t == Long.class) return integral(f, v, Long.MIN_VALUE, Long.MAX_VALUE);
        if (t == short.class || t == Short.class) return (short) integral(f, v, Short.MIN_VALUE, Short.MAX_VALUE);
        if (t == byte.class || t == Byte.class) return (byte) integral(f, v, Byte.MIN_VALUE, Byte.MAX_VALUE);
        if (t == double.class || t == Double.class) return number(f, v).doubleValue();
        if (t == float.class || t == Float.class) return number(f, v).floatValue();
        if (t == boolean.class || t == Boolean.class) {
            if (v instanceof Boolean) return v;
            throw wrong(f, v);
        }
        if (t == String.class) {
            if (v instanceof String) return v;
            throw wrong(f, v);
        }
        if (t == char.class || t == Character.class) {
            if (v instanceof String && ((String) v).length() == 1) return ((String) v).charAt(0);
            throw wrong(f, v);
        }
        if (t == java.math.BigDecimal.class) return new java.math.BigDecimal(number(f, v).toString());
        if (t == java.util.Date.class) return new java.util.Date(integral(f, v, Long.MIN_VALUE, Long.MAX_VALUE));
        if (t.isEnum()) {
            if (v instanceof String) {
                for (Object c : t.getEnumConstants()) if (((Enum<?>) c).name().equals(v)) return c;
            }
            throw new FactProblem(f.name, where + ": expected one of " + java.util.Arrays.toString(t.getEnumConstants()) + ", got " + describe(v));
        }
        TypeInfo nested = byClass.get(t);
        if (nested != null) {
            if (!(v instanceof Map)) throw wrong(f, v);
            try {
                return build(nested, (Map<?, ?>) v, depth + 1);
            } catch (FactProblem p) {
                throw new FactProblem(f.name + "." + p.field, where + ": " + p.getMessage());
            }
        }
        if (t.isInstance(v)) return v;  // Object, List, Map, Collection ...
        throw wrong(f, v);
    }

    private static long integral(FieldInfo f, Object v, long min, long max) throws FactProblem {
        if (!(v instanceof Long)) throw wrong(f, v);
        long l = (Long) v;
        if (l < min || l > max) throw new FactProblem(f.name, "field '" + f.name + "': " + l + " is out of range for " + typeName(f.type));
        return l;
    }

    private static Number number(FieldInfo f, Object v) throws FactProblem {
        if (v instanceof Long || v instanceof Double) return (Number) v;
        throw wrong(f, v);
    }

    private static FactProblem wrong(FieldInfo f, Object v) {
        return new FactProblem(f.name, "field '" + f.name + "': expected " + typeName(f.type) + ", got " + describe(v));
    }

    static String describe(Object v) {
        if (v == null) return "null";
        if (v instanceof String) {
            String s = (String) v;
            return "string \"" + (s.length() > 40 ? s.substring(0, 40) + "..." : s) + "\"";
        }
        if (v instanceof Long) return "integer " + v;
        if (v instanceof Double) return "number " + v;
        if (v instanceof Boolean) return "boolean " + v;
        if (v instanceof Map) return "an object";
        if (v instanceof List) return "a list";
        return v.getClass().getSimpleName();
    }

    /** Writes a declared fact as {"type": "Customer", field: value...}; false if not declared here. */
    boolean writeFact(StringBuilder b, Object fact) {
        TypeInfo t = byClass.get(fact.getClass());
        if (t == null) return false;
        b.append("{\"type\":");
        Json.quote(b, t.simpleName);
        for (FieldInfo f : t.fields.values()) {
            if (f.getter == null) continue;
            b.append(',');
            Json.quote(b, f.name);
            b.append(':');
            Json.write(b, f.value(fact), this);
        }
        b.append('}');
        return true;
    }

    /** The "id" of a declared fact if it has one, else null. */
    String idOf(Object fact) {
        TypeInfo t = byClass.get(fact.getClass());
        if (t == null) return null;
        FieldInfo f = t.fields.get("id");
        if (f == null || f.getter == null) return null;
        Object v = f.value(fact);
        return v == null ? null : String.valueOf(v);
    }
}
