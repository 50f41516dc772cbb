package org.printeps.gateway;

import java.util.ArrayList;
import java.util.Collections;
import java.util.HashMap;
import java.util.IdentityHashMap;
import java.util.List;
import java.util.Map;
import java.util.Objects;

import org.drools.model.functions.Function0;
import org.drools.model.functions.Function1;

/**
 * The facts of one one-shot fire ({@link Runner#fire}), by type and by the value of a field: what
 * the patterns of a request-join network read (built by {@link PlainRules#build} with
 * {@code requestJoins}). Every pattern after a rule's first reads its candidates here, through
 * Drools' {@code from}, when the rule's left side has a match, instead of every fact of its type
 * being stored in that pattern's memory on insert.
 *
 * Why: Drools 8.31 (Phreak) evaluates a rule lazily, but stages each inserted fact in the right
 * memory of every join, {@code not}, {@code exists} and accumulate over its type at once, also for
 * rules whose left side has no match and never will in this request, and takes it out again when
 * the session is emptied. At 10,000 business rules a 5-fact request staged ~13,000 right tuples
 * for ~74 firings: 80% of its time (docs/benchmarks.md, issue 30). A one-shot fire knows every fact
 * before it fires, and a rule base whose then-parts only call globals (plain rules) never changes
 * them while it fires: reading them here gives the same matches, in the order a right memory
 * holds them ({@link #of(Class)}), at the cost of a lookup per left match.
 *
 * The facts are those of the firing thread: {@link Runner#fire} opens and closes them around its
 * {@code fireAllRules}, which runs the rules on that thread.
 */
public final class RequestFacts {
    private static final ThreadLocal<RequestFacts> CURRENT = new ThreadLocal<RequestFacts>();

    private final List<Object> facts;
    private final Map<Class<?>, List<Object>> byType = new IdentityHashMap<Class<?>, List<Object>>();
    private final Map<Keyed, Map<Object, List<Object>>> byKey = new HashMap<Keyed, Map<Object, List<Object>>>();

    private RequestFacts(List<Object> facts) {
        this.facts = facts;
    }

    /** Makes {@code facts} (in insertion order) what the firing thread's request-join patterns read. */
    static void open(List<Object> facts) {
        CURRENT.set(new RequestFacts(facts));
    }

    /** Ends the request on this thread: a pattern read outside a request finds nothing. */
    static void close() {
        CURRENT.remove();
    }

    /**
     * The request's facts of {@code type} (instances of it or of a subtype, as a pattern matches),
     * last inserted first: the order a join's right memory holds them when a request's facts are
     * all staged before its fire (Drools stages each insert in front of the others), so a rule's
     * matches fire in the order the rule base's own network gives them.
     */
    List<Object> of(Class<?> type) {
        List<Object> found = byType.get(type);
        if (found == null) {
            found = new ArrayList<Object>();
            for (int k = facts.size() - 1; k >= 0; k--) if (type.isInstance(facts.get(k))) found.add(facts.get(k));
            byType.put(type, found);
        }
        return found;
    }

    /** Those of {@link #of(Class)} whose {@code field} equals {@code key} (a hash index built at the first read). */
    List<Object> of(Keyed keyed, Object key) {
        Map<Object, List<Object>> index = byKey.get(keyed);
        if (index == null) {
            index = new HashMap<Object, List<Object>>();
            for (Object f : of(keyed.type)) index.computeIfAbsent(keyed.field.apply(f), k -> new ArrayList<Object>(2)).add(f);
            byKey.put(keyed, index);
        }
        List<Object> found = index.get(key);
        return found == null ? Collections.emptyList() : found;
    }

    /** The firing thread's request facts of {@code type} (none outside a request). */
    static List<Object> read(Class<?> type) {
        RequestFacts request = CURRENT.get();
        return request == null ? Collections.emptyList() : request.of(type);
    }

    /** The firing thread's request facts of {@code keyed}'s type whose field equals {@code key}. */
    static List<Object> read(Keyed keyed, Object key) {
        RequestFacts request = CURRENT.get();
        return request == null ? Collections.emptyList() : request.of(keyed, key);
    }

    /** What a {@code not} or {@code exists} read from the request gives a match it holds for
     *  (the answer's facts of a firing leave it out, as Drools' own node adds nothing). */
    public static final class Marker {
        static final Marker INSTANCE = new Marker();

        private Marker() {}

        @Override public String toString() { return "(holds)"; }
    }

    /** An equality join's index ({@link Keyed}) and the variable its key is read from. */
    static final class KeyedSource {
        final Keyed keyed;
        final String ref;

        KeyedSource(Keyed keyed, String ref) {
            this.keyed = keyed;
            this.ref = ref;
        }
    }

    /**
     * {@code from} every request fact of a type. Equal sources (the same type) may share a node in
     * Drools' network, so equality is by type, never by the lambda's bytecode.
     */
    static final class All implements Function0<Object> {
        final Class<?> type;

        All(Class<?> type) { this.type = type; }

        public Object apply() {
            return read(type);
        }

        @Override public boolean equals(Object o) { return o instanceof All && ((All) o).type == type; }
        @Override public int hashCode() { return type.hashCode(); }
    }

    /**
     * {@code from} the request facts of a type whose {@code field} equals a value read from the left
     * match (an equality join): {@code of} reads that value from the variable the source is
     * declared on (the bound value itself, or a field of a bound fact). The pattern keeps its own
     * constraints, so the index only narrows the candidates: it is used for equality on text, int
     * and boolean fields, whose {@code equals} is the constraint's equality.
     */
    static final class Keyed implements Function1<Object, Object> {
        final Class<?> type;
        final Function1<Object, Object> field;
        final Function1<Object, Object> value;

        Keyed(Class<?> type, Function1<Object, Object> field, Function1<Object, Object> value) {
            this.type = type;
            this.field = field;
            this.value = value;
        }

        public Object apply(Object bound) {
            return read(this, value.apply(bound));
        }

        @Override
        public boolean equals(Object o) {
            if (!(o instanceof Keyed)) return false;
            Keyed k = (Keyed) o;
            return k.type == type && k.field.equals(field) && k.value.equals(value);  // Property compares by getter: shared across units as the rule base's join
        }

        @Override public int hashCode() { return Objects.hash(type, field, value); }
    }
}
