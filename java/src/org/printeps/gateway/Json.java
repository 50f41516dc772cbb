package org.printeps.gateway;

import java.util.ArrayList;
import java.util.Collection;
import java.util.Iterator;
import java.util.LinkedHashMap;
import java.util.List;
import java.util.Map;

/**
 * A small, strict JSON reader and writer.
 *
 * Why: facts cross the Python/Java boundary as one JSON string per request (one JPype call instead
 * of one per field), and the Drools jars carry no JSON library. Objects become LinkedHashMap, arrays
 * ArrayList, integers Long, other numbers Double. Nesting is bounded so hostile input cannot
 * overflow the stack.
 */
public final class Json {
    public static final int MAX_DEPTH = 64;

    /** Thrown for malformed input, with the character offset where it went wrong. */
    public static final class ParseException extends RuntimeException {
        public final int offset;
        ParseException(String message, int offset) {
            super(message + " at offset " + offset);
            this.offset = offset;
        }
    }

    private final String s;
    private int i;

    private Json(String s) { this.s = s; }

    public static Object parse(String text) {
        Json p = new Json(text);
        p.ws();
        Object v = p.value(0);
        p.ws();
        if (p.i != p.s.length()) throw new ParseException("unexpected trailing characters", p.i);
        return v;
    }

    private void ws() {
        while (i < s.length()) {
            char c = s.charAt(i);
            if (c == ' ' || c == '\n' || c == '\r' || c == '\t') i++; else break;
        }
    }

    private Object value(int depth) {
        if (depth > MAX_DEPTH) throw new ParseException("nesting deeper than " + MAX_DEPTH, i);
        if (i >= s.length()) throw new ParseException("unexpected end of input", i);
        char c = s.charAt(i);
        switch (c) {
            case '{': return object(depth);
            case '[': return array(depth);
            case '"': return string();
            case 't': return literal("true", Boolean.TRUE);
            case 'f': return literal("false", Boolean.FALSE);
            case 'n': return literal("null", null);
            default: return number();
        }
    }

    private Object literal(String word, Object v) {
        if (!s.startsWith(word, i)) throw new ParseException("unexpected character '" + s.charAt(i) + "'", i);
        i += word.length();
        return v;
    }

    private Map<String, Object> object(int depth) {
        Map<String, Object> m = new LinkedHashMap<String, Object>();
        i++;
        ws();
        if (i < s.length() && s.charAt(i) == '}') { i++; return m; }
        while (true) {
            ws();
            if (i >= s.length() || s.charAt(i) != '"') throw new ParseException("expected a field name", i);
            String k = string();
            ws();
            if (i >= s.length() || s.charAt(i) != ':') throw new ParseException("expected ':'", i);
            i++;
            ws();
            m.put(k, value(depth + 1));
            ws();
            if (i >= s.length()) throw new ParseException("unexpected end of input", i);
            char c = s.charAt(i++);
            if (c == '}') return m;
            if (c != ',') throw new ParseException("expected ',' or '}'", i - 1);
        }
    }

    private List<Object> array(int depth) {
        List<Object> l = new ArrayList<Object>();
        i++;
        ws();
        if (i < s.length() && s.charAt(i) == ']') { i++; return l; }
        while (true) {
            ws();
            l.add(value(depth + 1));
            ws();
            if (i >= s.length()) throw new ParseException("unexpected end of input", i);
            char c = s.charAt(i++);
            if (c == ']') return l;
            if (c != ',') throw new ParseException("expected ',' or ']'", i - 1);
        }
    }

    private String string() {
        i++;
        StringBuilder b = null;
        int start = i;
        while (i < s.length()) {
            char c = s.charAt(i);
            if (c == '"') {
                String out = b == null ? s.substring(start, i) : b.append(s, start, i).toString();
                i++;
                return out;
            }
            if (c == '\\') {
                if (b == null) b = new StringBuilder();
                b.append(s, start, i);
                i++;
                if (i >= s.length()) break;
                char e = s.charAt(i++);
                switch (e) {
                    case '"': b.append('"'); break;
                    case '\\': b.append('\\'); break;
                    case '/': b.append('/'); break;
                    case 'b': b.append('\b'); break;
                    case 'f': b.append('\f'); break;
                    case 'n': b.append('\n'); break;
                    case 'r': b.append('\r'); break;
                    case 't': b.append('\t'); break;
                    case 'u':
                        if (i + 4 > s.length()) throw new ParseException("bad unicode escape", i);
                        b.append((char) Integer.parseInt(s.substring(i, i + 4), 16));
                        i += 4;
                        break;
                    default: throw new ParseException("bad escape '\\" + e + "'", i - 1);
                }
                start = i;
            } else {
                i++;
            }
        }
        throw new ParseException("unterminated string", start);
    }

    private Object number() {
        int start = i;
        boolean integral = true;
        if (i < s.length() && (s.charAt(i) == '-')) i++;
        while (i < s.length()) {
            char c = s.charAt(i);
            if (c >= '0' && c <= '9') { i++; continue; }
            if (c == '.' || c == 'e' || c == 'E' || c == '+' || c == '-') { integral = false; i++; continue; }
            break;
        }
        String t = s.substring(start, i);
        if (t.isEmpty() || t.equals("-")) throw new ParseException("unexpected character '" + (i < s.length() ? s.charAt(i) : '?') + "'", start);
        try {
            if (integral) {
                if (t.length() < 19) return Long.valueOf(t);
                return Double.valueOf(t);  // beyond long: keep as a number, the field check will refuse it
            }
            return Double.valueOf(t);
        } catch (NumberFormatException ex) {
            throw new ParseException("bad number '" + t + "'", start);
        }
    }

    // ---------------------------------------------------------------- writing

    /** Writes a value; declared facts are written through {@code facts} (may be null). */
    public static void write(StringBuilder b, Object v, TypeRegistry facts) {
        if (v == null) { b.append("null"); return; }
        if (v instanceof String) { quote(b, (String) v); return; }
        if (v instanceof Boolean) { b.append(v.toString()); return; }
        if (v instanceof Double || v instanceof Float) {
            double d = ((Number) v).doubleValue();
            if (Double.isNaN(d) || Double.isInfinite(d)) b.append("null"); else b.append(d);
            return;
        }
        if (v instanceof Number) { b.append(v.toString()); return; }
        if (v instanceof Map) {
            b.append('{');
            boolean first = true;
            for (Object o : ((Map<?, ?>) v).entrySet()) {
                Map.Entry<?, ?> e = (Map.Entry<?, ?>) o;
                if (!first) b.append(',');
                first = false;
                quote(b, String.valueOf(e.getKey()));
                b.append(':');
                write(b, e.getValue(), facts);
            }
            b.append('}');
            return;
        }
        if (v instanceof Collection) {
            b.append('[');
            Iterator<?> it = ((Collection<?>) v).iterator();
            boolean first = true;
            while (it.hasNext()) {
                if (!first) b.append(',');
                first = false;
                write(b, it.next(), facts);
            }
            b.append(']');
            return;
        }
        if (v instanceof Object[]) {
            b.append('[');
            Object[] a = (Object[]) v;
            for (int k = 0; k < a.length; k++) {
                if (k > 0) b.append(',');
                write(b, a[k], facts);
            }
            b.append(']');
            return;
        }
        if (v instanceof Enum) { quote(b, ((Enum<?>) v).name()); return; }
        if (v instanceof java.util.Date) { b.append(((java.util.Date) v).getTime()); return; }
        if (facts != null && facts.writeFact(b, v)) return;
        quote(b, v.toString());
    }

    public static void quote(StringBuilder b, String s) {
        b.append('"');
        int plain = 0;  // most strings need no escape: copied in one append, not char by char
        while (plain < s.length()) {
            char c = s.charAt(plain);
            if (c < 0x20 || c == '"' || c == '\\') break;
            plain++;
        }
        b.append(s, 0, plain);
        for (int k = plain; k < s.length(); k++) {
            char c = s.charAt(k);
            switch (c) {
                case '"': b.append("\\\""); break;
                case '\\': b.append("\\\\"); break;
                case '\n': b.append("\\n"); break;
                case '\r': b.append("\\r"); break;
                case '\t': b.append("\\t"); break;
                default:
                    if (c < 0x20) b.append(String.format("\\u%04x", (int) c)); else b.append(c);
            }
        }
        b.append('"');
    }

    public static String toJson(Object v) {
        StringBuilder b = new StringBuilder();
        write(b, v, null);
        return b.toString();
    }
}
