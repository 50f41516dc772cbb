package org.printeps.gateway;

import java.util.HashMap;
import java.util.List;
import java.util.Map;
import java.util.Set;

import org.kie.api.event.rule.AgendaGroupPoppedEvent;
import org.kie.api.event.rule.DefaultAgendaEventListener;
import org.kie.api.event.rule.MatchCancelledEvent;
import org.kie.api.event.rule.MatchCreatedEvent;
import org.kie.api.runtime.KieSession;
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
    /**
     * The matches Drools put on the agenda (made, or re-activated after they fired) in a
     * propagation since the carry ({@link DroolsInternals#lastReachedBy} at least the mark when it
     * did), by identity: they fire, even if a later update from their own {@code no-loop} rule's
     * consequence (which Drools applies to the match without taking it off the agenda) left them
     * showing that update as their last. Kept by {@link #attach}'s listener until they fire or are
     * cancelled.
     */
    private final Set<Object> reached = java.util.Collections.newSetFromMap(new java.util.IdentityHashMap<Object, Boolean>());
    private KieSession attachedTo;
    private final DefaultAgendaEventListener listener = new DefaultAgendaEventListener() {
        @Override
        public void matchCreated(MatchCreatedEvent event) {
            Match match = event.getMatch();
            if (unchangedRules.contains(match.getRule().getName()) && DroolsInternals.lastReachedBy(match) >= mark) reached.add(match);
        }

        @Override
        public void matchCancelled(MatchCancelledEvent event) {
            reached.remove(event.getMatch());
        }

        @Override
        public void agendaGroupPopped(AgendaGroupPoppedEvent event) {
            String group = event.getAgendaGroup().getName();
            if (locked.contains(group)) poppedAt.putIfAbsent(group, DroolsInternals.propagationMark(attachedTo));
        }
    };

    /**
     * The agenda groups that were active (see {@link DroolsInternals#appliedFocusStack}) in the
     * session a durable snapshot was taken of, and the propagation number at which each was first
     * popped since. While such a group has not been popped, Drools in that session would discard a
     * re-activation of a fired match of its {@code lock-on-active} rules; the rebuilt session's
     * group is not active in that way (making it so would discard its pending matches too: they are
     * only evaluated at its first fire, after the propagations), so this filter drops those.
     * A pop ends it, and so does a {@code set_focus} command of another group after the carry (see
     * {@link #pushed}): Drools deactivates the group the push goes over. (The agenda's push events
     * cannot tell: the pushes that restore the stack look the same.)
     */
    private Set<String> locked = java.util.Collections.emptySet();
    private final Map<String, Long> poppedAt = new HashMap<String, Long>();

    /**
     * A {@code set_focus} of {@code group} ran after the carry: every other group locked here is
     * no longer active in a session never rebuilt either (Drools deactivates the focus a push goes
     * over; a push of the focused group itself changes nothing), so its lock ends now.
     */
    void pushed(String group) {
        for (String g : locked) {
            if (!g.equals(group)) poppedAt.putIfAbsent(g, DroolsInternals.propagationMark(attachedTo));
        }
    }

    /** See {@link #locked}. */
    Refraction locking(Set<String> activeGroups) {
        this.locked = activeGroups;
        return this;
    }

    /** Whether a propagation numbered {@code n} reached a match of {@code rule} while its lock-on-active group was still locked. */
    private boolean lockedOut(Match match, long n) {
        if (locked.isEmpty()) return false;
        String group = DroolsInternals.lockOnActiveGroup(match.getRule());
        if (group == null || !locked.contains(group)) return false;
        Long popped = poppedAt.get(group);
        return popped == null || n < popped;
    }

    /** Listens to {@code session}'s agenda for the matches propagations since the carry put on it (see {@link #reached}). */
    Refraction attach(KieSession session) {
        session.addEventListener(listener);
        attachedTo = session;
        return this;
    }

    /** Stops listening (the session drops this filter). */
    void detach() {
        if (attachedTo != null) attachedTo.removeEventListener(listener);
        attachedTo = null;
        reached.clear();
    }

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
        boolean put = reached.remove(match);  // put on the agenda by a propagation since the carry
        long n = DroolsInternals.lastReachedBy(match);
        if ((put || n >= mark) && !lockedOut(match, n)) return true;  // made or re-activated since the carry
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
