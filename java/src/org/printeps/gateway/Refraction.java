package org.printeps.gateway;

import java.util.HashMap;
import java.util.List;
import java.util.Map;
import java.util.Set;

import org.kie.api.runtime.rule.AgendaFilter;
import org.kie.api.runtime.rule.Match;

/**
 * Drools' refraction carried across a move to a new rule set version: a session that moved (see
 * {@link Session#moveFrom}) holds the old session's facts re-inserted, so every rule matches them
 * afresh. This filter drops exactly the matches the old session had already fired: those the new
 * version holds right after the move (its first agenda over the facts that came across) of a rule
 * whose text did not change, minus the ones still pending in the old session (as multisets: two
 * matches can share a key). Each is dropped once.
 *
 * <p>Why not "drop every match of an unchanged rule over unchanged facts unless it was pending":
 * a match can arise only after the move, when another rule fires — a {@code not} or an
 * {@code accumulate} over other facts becoming true (the reception's "Pair" after "Adult" typed the
 * customers) — while its own facts are the unchanged ones; it never fired, and must fire now, as
 * {@code KieContainer.updateToVersion} would. It applies until a fire empties the agenda.
 */
final class Refraction implements AgendaFilter {
    private final Set<String> unchangedRules;
    private final Set<Object> unchangedFacts;   // identity set, shared with Handles
    private final Map<String, Integer> fired;    // keys (a multiset: query rows can share one) of matches fired already

    Refraction(Set<String> unchangedRules, Set<Object> unchangedFacts, Map<String, Integer> fired) {
        this.unchangedRules = unchangedRules;
        this.unchangedFacts = unchangedFacts;
        this.fired = fired;
    }

    /**
     * A match's key: its rule and, per object, the identity of the fact (through {@code mapped}
     * from an old session's object to the one that came across, when given) or, for an object that
     * is no fact that came across unchanged (an accumulate's result, a modified or new fact), its
     * value: a count of 1 and a count of 2 are different matches.
     */
    static String key(String rule, List<?> objects, Map<Object, Object> mapped, Set<Object> facts) {
        StringBuilder b = new StringBuilder(rule);
        for (Object o : objects) {
            b.append('|');
            part(b, o, mapped, facts, 0);
        }
        return b.toString();
    }

    /** One object of a key: a fact by identity, a value (an accumulate's result, a query's row) by its content. */
    private static void part(StringBuilder b, Object o, Map<Object, Object> mapped, Set<Object> facts, int depth) {
        Object m = mapped == null ? o : mapped.get(o);
        if (m != null && facts.contains(m)) {
            b.append('#').append(System.identityHashCode(m));
        } else if (o == null || o instanceof Number || o instanceof CharSequence || o instanceof Boolean || o instanceof Character) {
            b.append('=').append(o);
        } else if (depth < 4 && (o instanceof Iterable || o instanceof Object[])) {
            b.append('[');
            for (Object e : o instanceof Object[] ? java.util.Arrays.asList((Object[]) o) : (Iterable<?>) o) {
                part(b, e, mapped, facts, depth + 1);
                b.append(',');
            }
            b.append(']');
        } else {
            b.append('~').append(o.getClass().getName());  // a modified or new fact, or a value of no stable text
        }
    }

    @Override
    public boolean accept(Match match) {
        String rule = match.getRule().getName();
        if (!unchangedRules.contains(rule)) return true;
        return !take(fired, key(rule, match.getObjects(), null, unchangedFacts));
    }

    /** A multiset of keys (two matches can have one key: rows of a query without outputs). */
    static Map<String, Integer> emptyKeys() { return new HashMap<String, Integer>(); }

    static void add(Map<String, Integer> keys, String key) { keys.merge(key, 1, Integer::sum); }

    /** Removes one ``key``; false if there was none. */
    static boolean take(Map<String, Integer> keys, String key) {
        Integer n = keys.get(key);
        if (n == null) return false;
        if (n <= 1) keys.remove(key); else keys.put(key, n - 1);
        return true;
    }

    /** {@code from} minus {@code minus}, as multisets (in place). */
    static void subtract(Map<String, Integer> from, Map<String, Integer> minus) {
        for (Map.Entry<String, Integer> e : minus.entrySet()) {
            for (int k = 0; k < e.getValue(); k++) take(from, e.getKey());
        }
    }
}
