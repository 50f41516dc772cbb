package org.printeps.gateway;

import java.util.ArrayList;
import java.util.Arrays;
import java.util.Comparator;
import java.util.HashMap;
import java.util.IdentityHashMap;
import java.util.List;
import java.util.Map;

import org.drools.core.base.ClassObjectType;
import org.drools.core.common.InternalAgenda;
import org.drools.core.common.InternalFactHandle;
import org.drools.core.common.ReteEvaluator;
import org.drools.core.impl.RuleBase;
import org.drools.core.phreak.RuleAgendaItem;
import org.drools.core.reteoo.AlphaNode;
import org.drools.core.reteoo.AlphaTerminalNode;
import org.drools.core.reteoo.BetaNode;
import org.drools.core.reteoo.CompositeObjectSinkAdapter;
import org.drools.core.reteoo.ExistsNode;
import org.drools.core.reteoo.JoinNode;
import org.drools.core.reteoo.LeftInputAdapterNode;
import org.drools.core.reteoo.LeftTupleSink;
import org.drools.core.reteoo.LeftTupleSource;
import org.drools.core.reteoo.ObjectSink;
import org.drools.core.reteoo.ObjectSinkPropagator;
import org.drools.core.reteoo.ObjectTypeNode;
import org.drools.core.reteoo.TerminalNode;
import org.drools.core.rule.EntryPointId;
import org.drools.core.util.LinkedList;
import org.kie.api.KieBase;
import org.kie.api.runtime.KieSession;
import org.kie.api.runtime.rule.FactHandle;

/**
 * The Drools seam's second file (with {@link DroolsInternals}): the order in which a rule base's
 * own network links its eager rules (auto-focus) when a fact is inserted, so that a request-join
 * network ({@link RequestFacts}), whose alpha network is another, evaluates them in that order.
 *
 * Why it matters: Drools evaluates eager rules in the order they get linked (the agenda's eager
 * list), and each auto-focus rule that matches pushes its agenda group onto the focus stack, so
 * that order decides which group fires first. A fact links rules in the order its type's node
 * propagates it to their nodes, and that order depends on every pattern on the type: which alpha
 * nodes are hashed or range-indexed (three or more on one field) and in what order they were
 * added. The request-join network reads most patterns from the request, so its type nodes hold
 * other alpha nodes and link the same rules in another order (15–76% of requests of 3,000-rule
 * business sets fired their groups in another order before this).
 *
 * How: {@link #of} walks the rule base's alpha network once, in the order
 * {@code CompositeObjectSinkAdapter.propagateAssertObject} visits it, and numbers the nodes that
 * link a rule: left input adapters and the right inputs of joins and {@code exists} (a
 * {@code not}, accumulate or {@code from} is linked from the start). A fire ({@link Fire}) inserts
 * the request's facts one at a time, lets Drools propagate each ({@code flushPropagations}) and,
 * when one fact linked two eager rules or more, sorts those in the eager list by the number of
 * the node that completed each rule's links in the rule base: the last one, in that order, the
 * fact reaches of the nodes no earlier fact reached. Equal numbers (two rules linked by one node)
 * keep the order Drools gave them.
 *
 * Assumes (8.31.1.Final; {@code tests/engine/test_drools_seam.py} checks it): a type node's
 * propagator is a {@code CompositeObjectSinkAdapter} (visiting hashed alpha nodes per field in
 * {@code getHashedFieldIndexes()} order, then range-indexed ones per {@code getRangeIndexMap()}
 * entry in {@code AlphaRangeIndex.getAllValues()} order, then {@code getHashableSinks()},
 * {@code getRangeIndexableSinks()}, {@code getOthers()}) or a single/empty adapter listing
 * {@code getSinks()}; a fact visits the type nodes it belongs to by node id
 * ({@code ClassObjectTypeConf}); the agenda ({@code KieSession.getAgenda()}) is a
 * {@code DefaultAgenda} holding the eager rules in its private {@code LinkedList} field
 * {@code eager}, which only {@code fireAllRules} empties; {@code ReteooBuilder.getTerminalNodes()}
 * lists every rule's terminal nodes.
 */
public final class DroolsLinkOrder {
    private static final String EAGER_FIELD = "eager";
    private static volatile java.lang.reflect.Field eagerField;

    /** A node that links rules when a fact reaches it: its type, its number, the alpha tests on the way. */
    private static final class Place {
        final Class<?> type;
        final long number;
        final AlphaNode[] path;

        Place(Class<?> type, long number, AlphaNode[] path) {
            this.type = type;
            this.number = number;
            this.path = path;
        }

        boolean reaches(InternalFactHandle h, ReteEvaluator session) {
            if (!type.isInstance(h.getObject())) return false;
            for (AlphaNode a : path) if (!a.getConstraint().isAllowed(h, session)) return false;
            return true;
        }
    }

    /** Each eager rule's linking nodes, by "rule's full name#subrule". */
    private final Map<String, Place[]> links;

    /** The rule base's auto-focus rules of one pattern, per fact type, in the order a fact reaches them. */
    private final Map<Class<?>, List<String>> focus;

    private DroolsLinkOrder(Map<String, Place[]> links, Map<Class<?>, List<String>> focus) {
        this.links = links;
        this.focus = focus;
    }

    /**
     * The link order of {@code kb}'s eager rules; null when it has none (Drools' order needs no
     * help); throws {@link IllegalStateException} when a rule's linking node is not where the walk
     * looks (another propagator, another entry point): then no request-join network can fire as
     * {@code kb} does.
     */
    public static DroolsLinkOrder of(KieBase kb) {
        RuleBase base = (RuleBase) kb;
        Map<String, Place[]> links = new HashMap<String, Place[]>();
        Map<Object, Place> places = null;
        for (TerminalNode[] terminals : base.getReteooBuilder().getTerminalNodes().values()) {
            for (TerminalNode t : terminals) {
                if (!t.getRule().isEager()) continue;
                if (places == null) places = places(base);
                links.put(key(t), linking(t, places));
            }
        }
        return links.isEmpty() ? null : new DroolsLinkOrder(links, focusAtPropagation(places));
    }

    private static String key(TerminalNode t) {
        return t.getRule().getFullyQualifiedName() + "#" + t.getSubruleIndex();
    }

    /** The nodes of a rule's path that a fact must reach before the rule is linked. */
    private static Place[] linking(TerminalNode t, Map<Object, Place> places) {
        List<Place> out = new ArrayList<Place>();
        for (LeftTupleSource s = t.getLeftTupleSource(); s != null; s = s.getLeftTupleSource()) {
            boolean adapter = s instanceof LeftInputAdapterNode;
            boolean linksOnRight = (s instanceof JoinNode || s instanceof ExistsNode) && !((BetaNode) s).isRightInputIsRiaNode();
            if (adapter || linksOnRight) {
                Place p = places.get(s);
                if (p == null) throw new IllegalStateException("rule '" + t.getRule().getName() + "': node " + s + " is not in the alpha network of the default entry point");
                out.add(p);
            }
            if (adapter) break;
        }
        return out.toArray(new Place[0]);
    }

    /** Every node under the default entry point's type nodes that is not an alpha node, numbered in propagation order. */
    private static Map<Object, Place> places(RuleBase base) {
        Map<Object, Place> out = new IdentityHashMap<Object, Place>();
        List<ObjectTypeNode> types = new ArrayList<ObjectTypeNode>(base.getRete().getObjectTypeNodes(EntryPointId.DEFAULT).values());
        types.sort(Comparator.comparingInt(ObjectTypeNode::getId));
        long[] counter = {0};
        for (ObjectTypeNode otn : types) {
            if (!(otn.getObjectType() instanceof ClassObjectType)) continue;
            Class<?> type = ((ClassObjectType) otn.getObjectType()).getClassType();
            walk(otn.getObjectSinkPropagator(), type, new AlphaNode[0], counter, out);
        }
        return out;
    }

    private static void walk(ObjectSinkPropagator p, Class<?> type, AlphaNode[] path, long[] counter, Map<Object, Place> out) {
        if (!(p instanceof CompositeObjectSinkAdapter)) {
            for (ObjectSink s : p.getSinks()) visit(s, type, path, counter, out);
            return;
        }
        CompositeObjectSinkAdapter c = (CompositeObjectSinkAdapter) p;
        if (c.getHashedFieldIndexes() != null) {
            for (CompositeObjectSinkAdapter.FieldIndex f : c.getHashedFieldIndexes()) {
                if (!f.isHashed()) continue;
                for (Map.Entry<CompositeObjectSinkAdapter.HashKey, AlphaNode> e : c.getHashedSinkMap().entrySet()) {
                    if (e.getKey().getIndex() == f.getIndex()) visit(e.getValue(), type, path, counter, out);
                }
            }
        }
        if (c.getRangeIndexMap() != null) {
            for (Map.Entry<CompositeObjectSinkAdapter.FieldIndex, org.drools.core.util.index.AlphaRangeIndex> e : c.getRangeIndexMap().entrySet()) {
                if (!e.getKey().isRangeIndexed()) continue;
                for (AlphaNode a : e.getValue().getAllValues()) visit(a, type, path, counter, out);
            }
        }
        if (c.getHashableSinks() != null) for (AlphaNode a : c.getHashableSinks()) visit(a, type, path, counter, out);
        if (c.getRangeIndexableSinks() != null) for (AlphaNode a : c.getRangeIndexableSinks()) visit(a, type, path, counter, out);
        if (c.getOthers() != null) for (Object s : c.getOthers()) visit((ObjectSink) s, type, path, counter, out);
    }

    private static void visit(ObjectSink s, Class<?> type, AlphaNode[] path, long[] counter, Map<Object, Place> out) {
        if (s instanceof AlphaNode) {
            AlphaNode[] longer = Arrays.copyOf(path, path.length + 1);
            longer[path.length] = (AlphaNode) s;
            walk(((AlphaNode) s).getObjectSinkPropagator(), type, longer, counter, out);
        } else {
            out.put(s, new Place(type, counter[0]++, path));
        }
    }

    /**
     * Whether a fact reaches the auto-focus rules of one pattern in {@code joins} (a request-join
     * network of this rule base's rules) in the order it reaches them in the rule base (walked
     * once, by {@link #of}). Such a rule is an
     * alpha terminal node: Drools makes its match, and pushes its agenda group, the moment a fact
     * reaches it, not through the eager list {@link Fire} orders. Where the request-join network's
     * alpha nodes have other children than the rule base's (the patterns it reads from the request
     * are not there), Drools may order the children otherwise (it hashes and range-indexes
     * children by how many test one field), and the groups would take the focus in another order:
     * then the set keeps the rule base's network ({@code Runner}).
     */
    public boolean sameFocusOrder(KieBase joins) {
        return focus.equals(focusAtPropagation(places((RuleBase) joins)));
    }

    /** The auto-focus rules of one pattern, by name, in the order a fact reaches them (all types; for tests of this seam). */
    public static List<String> focusOrder(KieBase kb) {
        List<String> out = new ArrayList<String>();
        for (List<String> keys : focusAtPropagation(places((RuleBase) kb)).values()) {
            for (String k : keys) out.add(k.substring(k.lastIndexOf('.') + 1, k.lastIndexOf('#')));
        }
        return out;
    }

    /** Per fact type, the auto-focus rules of one pattern in the order a fact reaches them ({@code places}: a network's walk). */
    private static Map<Class<?>, List<String>> focusAtPropagation(Map<Object, Place> places) {
        List<Map.Entry<Object, Place>> terminals = new ArrayList<Map.Entry<Object, Place>>();
        for (Map.Entry<Object, Place> e : places.entrySet()) {
            if (e.getKey() instanceof AlphaTerminalNode) terminals.add(e);
        }
        terminals.sort(Comparator.comparingLong(e -> e.getValue().number));
        Map<Class<?>, List<String>> out = new HashMap<Class<?>, List<String>>();
        for (Map.Entry<Object, Place> e : terminals) {
            for (LeftTupleSink sink : ((AlphaTerminalNode) e.getKey()).getSinkPropagator().getSinks()) {
                if (sink instanceof TerminalNode && ((TerminalNode) sink).getRule().getAutoFocus()) {
                    out.computeIfAbsent(e.getValue().type, k -> new ArrayList<String>()).add(key((TerminalNode) sink));
                }
            }
        }
        return out;
    }

    /** One fire's insertions into a session of the request-join network. */
    public Fire begin(KieSession session) {
        return new Fire(session);
    }

    /** Call {@link #inserted} after each fact is inserted (and before the next). */
    public final class Fire {
        private final InternalAgenda agenda;
        private final ReteEvaluator evaluator;
        private final LinkedList<RuleAgendaItem> eager;
        private final List<InternalFactHandle> earlier = new ArrayList<InternalFactHandle>();
        private int known;

        Fire(KieSession session) {
            this.agenda = (InternalAgenda) session.getAgenda();
            this.evaluator = (ReteEvaluator) session;
            this.eager = eagerList(agenda);
            this.known = eager.size();
        }

        /** Propagates the fact just inserted and puts the eager rules it linked in the rule base's order. */
        public void inserted(FactHandle handle) {
            InternalFactHandle h = (InternalFactHandle) handle;
            agenda.flushPropagations();
            int added = eager.size() - known;
            if (added >= 2) reorder(added, h);
            known = eager.size();
            earlier.add(h);
        }

        private void reorder(int added, InternalFactHandle h) {
            RuleAgendaItem[] items = new RuleAgendaItem[added];
            RuleAgendaItem item = eager.getLast();
            for (int k = added - 1; k >= 0; k--, item = item.getPrevious()) items[k] = item;
            long[] numbers = new long[added];
            Integer[] order = new Integer[added];
            for (int k = 0; k < added; k++) {
                numbers[k] = linkedAt(items[k], h);
                order[k] = k;
            }
            Arrays.sort(order, Comparator.comparingLong(k -> numbers[k]));  // stable: ties keep Drools' order
            boolean same = true;
            for (int k = 0; k < added; k++) same &= order[k] == k;
            if (same) return;
            for (RuleAgendaItem one : items) eager.remove(one);
            for (Integer k : order) eager.add(items[k]);
        }

        /** The number of the node at which {@code h} completed the item's links in the rule base (unknown: last). */
        private long linkedAt(RuleAgendaItem item, InternalFactHandle h) {
            Place[] places = links.get(key(item.getTerminalNode()));
            if (places == null) return Long.MAX_VALUE;
            long at = -1;
            for (Place p : places) {
                if (p.number > at && p.reaches(h, evaluator) && !reachedEarlier(p)) at = p.number;
            }
            return at < 0 ? Long.MAX_VALUE : at;
        }

        private boolean reachedEarlier(Place p) {
            for (InternalFactHandle g : earlier) if (p.reaches(g, evaluator)) return true;
            return false;
        }
    }

    /** The rules in {@code session}'s eager list, in order, after propagating what is queued (for tests of this seam). */
    public static List<String> eagerRules(KieSession session) {
        InternalAgenda agenda = (InternalAgenda) session.getAgenda();
        agenda.flushPropagations();
        List<String> out = new ArrayList<String>();
        for (RuleAgendaItem item = eagerList(agenda).getFirst(); item != null; item = item.getNext()) out.add(item.getRule().getName());
        return out;
    }

    @SuppressWarnings("unchecked")
    private static LinkedList<RuleAgendaItem> eagerList(InternalAgenda agenda) {
        try {
            java.lang.reflect.Field f = eagerField;
            if (f == null || !f.getDeclaringClass().isInstance(agenda)) {
                f = agenda.getClass().getDeclaredField(EAGER_FIELD);
                f.setAccessible(true);
                eagerField = f;
            }
            return (LinkedList<RuleAgendaItem>) f.get(agenda);
        } catch (ReflectiveOperationException | RuntimeException e) {
            throw new IllegalStateException("Drools' agenda " + agenda.getClass().getName() + " has no readable eager list ("
                    + EAGER_FIELD + "): " + e, e);
        }
    }
}
