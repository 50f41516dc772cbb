package org.printeps.gateway;

import java.util.HashMap;
import java.util.List;
import java.util.Map;
import java.util.Set;

import org.kie.api.runtime.rule.AgendaFilter;
import org.kie.api.runtime.rule.FactHandle;
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
 * {@code KieContainer.updateToVersion} would.
 *
 * <p>The same filter carries a durable session's snapshot (see {@link Carry#refract}): there the
 * keys name facts by their place in the snapshot (so a snapshot's pending matches, written as
 * keys, mean the same in the process that restores it), and "fired" is every match of the
 * restored facts, in every agenda group, minus the ones pending when the snapshot was taken.
 * It applies until each of its keys was dropped once: a key of an agenda group that has no focus
 * waits for the group to be focused and fired.
 *
 * <p>Which matches it keys: only those no propagation reached since the carry ({@link
 * DroolsInternals#lastReachedBy} below the mark taken once the facts were in), and those by the
 * place of their fact handles, whatever was changed in the facts since. A fact modified in a
 * property its rule does not listen to (property reactivity) leaves the match as it was: it had
 * fired, and stays fired, as in a session never carried. A match something reached since (an
 * insert made it, or a modify its rule listens to re-activated it) is let through: in a session
 * never carried it is on the agenda too.
 */
final class Refraction implements AgendaFilter {
    private final Set<String> unchangedRules;
    private final Map<String, Integer> fired;    // keys (a multiset: query rows can share one) of matches fired already
    private final Map<Object, Integer> places;   // a fact's place in the carried state (identity map)
    private final Map<FactHandle, Integer> handles;  // the place of the fact each carried handle was made for (identity map)
    private final long mark;                     // propagations numbered at least this came after the carry

    Refraction(Set<String> unchangedRules, Map<String, Integer> fired, Map<Object, Integer> places, Map<FactHandle, Integer> handles,
               long mark) {
        this.unchangedRules = unchangedRules;
        this.fired = fired;
        this.places = places;
        this.handles = handles;
        this.mark = mark;
    }

    /** Whether every key was dropped (the filter has nothing left to do). */
    boolean spent() { return fired.isEmpty(); }

    /** The places of {@code facts} (in order) by identity: what keys name facts by. */
    static Map<Object, Integer> places(List<Object> facts) {
        Map<Object, Integer> out = new java.util.IdentityHashMap<Object, Integer>();
        for (int k = 0; k < facts.size(); k++) if (facts.get(k) != null) out.put(facts.get(k), k);
        return out;
    }

    /**
     * A match's key: its rule and, per object, the place of the fact (through {@code mapped}
     * from an old session's object to the one that came across, when given) or, for an object that
     * is no fact that came across unchanged (an accumulate's result, a modified or new fact), its
     * value: a count of 1 and a count of 2 are different matches.
     */
    static String key(String rule, List<?> objects, Map<Object, Object> mapped, Set<Object> facts, Map<Object, Integer> places) {
        StringBuilder b = new StringBuilder(rule);
        for (Object o : objects) {
            b.append('|');
            part(b, o, mapped, facts, places, 0);
        }
        return b.toString();
    }

    /** One object of a key: a fact by its place, a value (an accumulate's result, a query's row) by its content. */
    private static void part(StringBuilder b, Object o, Map<Object, Object> mapped, Set<Object> facts, Map<Object, Integer> places,
                             int depth) {
        Object m = mapped == null ? o : mapped.get(o);
        Integer place = m == null ? null : places.get(m);
        if (place != null && facts.contains(m)) {
            b.append('#').append(place);
        } else if (o == null || o instanceof Number || o instanceof CharSequence || o instanceof Boolean || o instanceof Character) {
            b.append('=').append(o);
        } else if (depth < 4 && (o instanceof Iterable || o instanceof Object[])) {
            b.append('[');
            for (Object e : o instanceof Object[] ? java.util.Arrays.asList((Object[]) o) : (Iterable<?>) o) {
                part(b, e, mapped, facts, places, depth + 1);
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
        if (DroolsInternals.lastReachedBy(match) >= mark) return true;  // made or re-activated since the carry
        return !take(fired, carriedKey(rule, match.getFactHandles()));
    }

    /**
     * The key of a match nothing reached since the carry, by its handles: a carried handle names its
     * fact's place even if the fact was changed since (in a property the rule does not listen to,
     * or the match would have been reached); any other object (an accumulate's result, a
     * {@code from}'s element) is named as {@link #key} names it.
     */
    private String carriedKey(String rule, List<? extends FactHandle> matched) {
        StringBuilder b = new StringBuilder(rule);
        for (FactHandle h : matched) {
            b.append('|');
            Integer place = handles.get(h);
            if (place != null) b.append('#').append(place);
            else part(b, DroolsInternals.objectOf(h), null, places.keySet(), places, 0);
        }
        return b.toString();
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
