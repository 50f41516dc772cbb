package org.printeps.gateway;

import java.util.HashSet;
import java.util.List;
import java.util.Set;

import org.kie.api.runtime.rule.AgendaFilter;
import org.kie.api.runtime.rule.Match;

/**
 * Drools' refraction carried across a move to a new rule set version: a session that moved (see
 * {@link Session#moveFrom}) holds the old session's facts re-inserted, so every rule matches them
 * afresh. This filter drops the matches the old session had already fired — those of a rule whose
 * text did not change, over facts that came across and were not changed since — and lets through
 * what {@code KieContainer.updateToVersion} would fire: new and changed rules, matches that were
 * still pending when the move happened, and anything involving facts inserted or modified later.
 * It applies until a fire empties the agenda.
 */
final class Refraction implements AgendaFilter {
    private final Set<String> unchangedRules;
    private final Set<Object> unchangedFacts;   // identity set, shared with Handles
    private final Set<String> pending;           // rule + identities of the facts of a pending match

    Refraction(Set<String> unchangedRules, Set<Object> unchangedFacts, Set<String> pending) {
        this.unchangedRules = unchangedRules;
        this.unchangedFacts = unchangedFacts;
        this.pending = pending;
    }

    static String key(String rule, List<?> objects, java.util.Map<Object, Object> mapped) {
        StringBuilder b = new StringBuilder(rule);
        for (Object o : objects) {
            Object m = mapped == null ? o : mapped.get(o);
            b.append('|').append(m == null ? "?" : String.valueOf(System.identityHashCode(m)));
        }
        return b.toString();
    }

    @Override
    public boolean accept(Match match) {
        String rule = match.getRule().getName();
        if (!unchangedRules.contains(rule)) return true;
        List<Object> objects = match.getObjects();
        if (objects.isEmpty()) return true;
        for (Object o : objects) {
            if (!unchangedFacts.contains(o)) return true;
        }
        return pending.remove(key(rule, objects, null));
    }

    static Set<String> emptyPending() { return new HashSet<String>(); }
}
