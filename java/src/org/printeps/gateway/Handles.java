package org.printeps.gateway;

import java.util.HashMap;
import java.util.HashSet;
import java.util.Map;
import java.util.Set;

import org.kie.api.event.rule.ObjectDeletedEvent;
import org.kie.api.event.rule.ObjectInsertedEvent;
import org.kie.api.event.rule.ObjectUpdatedEvent;
import org.kie.api.event.rule.RuleRuntimeEventListener;
import org.kie.api.runtime.KieSession;
import org.kie.api.runtime.rule.EntryPoint;
import org.kie.api.runtime.rule.FactHandle;

/**
 * The fact handles of one session in KIE's external form
 * ({@code 0:id:identityHashCode:objectHashCode:recency:entryPoint:traitType:className}), and their
 * way back from that text to the live handle.
 *
 * Why a registry of our own: a client holds the text of a handle across calls (KIE Server returns
 * it from {@code insert}); Drools resolves such a handle by its id alone, so a handle of a
 * disposed session silently hits whatever fact now has that id. Here a handle resolves only when
 * its id is live in this session and its identity hash is one the fact has had (an update swaps
 * the object, and with it the hash), so stale handles are reported, not misapplied. After a
 * session moved to a new rule set version (see {@link Session#moveFrom}) the handles clients hold
 * from before are kept as aliases of the facts' new handles.
 */
final class Handles implements RuleRuntimeEventListener {

    /** A live handle and every identity hash its object has had (the text clients may hold). */
    static final class Entry {
        final FactHandle handle;
        final Set<Integer> hashes = new HashSet<Integer>(2);
        Entry(FactHandle handle) {
            this.handle = handle;
            hashes.add(DroolsInternals.identityHashCode(handle));
        }
    }

    private final Map<Long, Entry> byId = new HashMap<Long, Entry>();
    /** "id:identityHash" of a handle from before a move -> the entry of its fact now. */
    private final Map<String, Entry> aliases = new HashMap<String, Entry>();
    @Override
    public void objectInserted(ObjectInsertedEvent event) {
        FactHandle h = event.getFactHandle();
        byId.put(DroolsInternals.handleId(h), new Entry(h));
    }

    @Override
    public void objectUpdated(ObjectUpdatedEvent event) {
        FactHandle h = event.getFactHandle();
        Entry e = byId.get(DroolsInternals.handleId(h));
        if (e != null) e.hashes.add(DroolsInternals.identityHashCode(h));
    }

    @Override
    public void objectDeleted(ObjectDeletedEvent event) {
        FactHandle h = event.getFactHandle();
        Entry e = byId.remove(DroolsInternals.handleId(h));
        if (e != null) aliases.values().removeIf(x -> x == e);
    }

    /** Registers a handle from before a move as an alias of the fact's handle now. */
    void alias(long oldId, int oldHash, FactHandle now) {
        Entry e = byId.get(DroolsInternals.handleId(now));
        if (e != null) aliases.put(oldId + ":" + oldHash, e);
    }

    /** The aliases this registry resolves (old "id:hash" -> live handle), to carry into a next move. */
    Map<String, FactHandle> aliasHandles() {
        Map<String, FactHandle> out = new HashMap<String, FactHandle>();
        for (Map.Entry<String, Entry> a : aliases.entrySet()) out.put(a.getKey(), a.getValue().handle);
        return out;
    }

    /** Thrown when a handle's text does not name a live fact of this session. */
    static final class Stale extends Exception {
        Stale(String message) { super(message); }
    }

    /** The live handle that {@code text} names, or {@link Stale} saying why there is none. */
    FactHandle resolve(String text) throws Stale {
        String[] parts = text == null ? new String[0] : text.trim().split(":");
        long id;
        Integer hash = null;
        try {
            if (parts.length < 2) throw new NumberFormatException();
            id = Long.parseLong(parts[1]);
            if (parts.length > 2 && !parts[2].isEmpty()) hash = Integer.valueOf(parts[2]);
        } catch (NumberFormatException e) {
            throw new Stale("'" + text + "' is not a fact handle (KIE's external form is "
                    + "0:id:identityHashCode:objectHashCode:recency:entryPoint:traitType:className)");
        }
        if (hash != null) {
            Entry alias = aliases.get(id + ":" + hash);
            if (alias != null) return alias.handle;
        }
        Entry e = byId.get(id);
        if (e == null) {
            throw new Stale("fact handle " + text + " is not in this session (retracted, or from a session that was disposed)");
        }
        if (hash != null && !e.hashes.contains(hash)) {
            throw new Stale("fact handle " + text + " does not belong to this session (a handle of a disposed "
                    + "session, or of another one: this session's fact " + id + " is " + external(e.handle) + ")");
        }
        return e.handle;
    }

    static String external(FactHandle h) {
        return h.toExternalForm();
    }

    /** Every live handle of the session, in id order, over all its entry points. */
    static java.util.List<FactHandle> all(KieSession session) {
        java.util.List<FactHandle> out = new java.util.ArrayList<FactHandle>();
        for (EntryPoint ep : session.getEntryPoints()) out.addAll(ep.getFactHandles());
        out.sort((a, b) -> Long.compare(DroolsInternals.handleId(a), DroolsInternals.handleId(b)));
        return out;
    }

    /**
     * Every "id:hash" text that resolves to {@code h} here: its id with each identity hash its
     * object has had, and the aliases of it. A durable session's snapshot carries them, so the
     * handles clients hold still resolve after the session is rebuilt in another process.
     */
    java.util.List<String> keysOf(FactHandle h) {
        java.util.List<String> out = new java.util.ArrayList<String>();
        long id = DroolsInternals.handleId(h);
        Entry e = byId.get(id);
        if (e == null) {
            out.add(id + ":" + DroolsInternals.identityHashCode(h));
            return out;
        }
        for (Integer hash : e.hashes) out.add(id + ":" + hash);
        for (Map.Entry<String, Entry> a : aliases.entrySet()) if (a.getValue() == e) out.add(a.getKey());
        return out;
    }

    /**
     * {@link #keysOf} of every live handle, by handle id, in one pass over the aliases: what a
     * snapshot writes. Why not keysOf per handle: each scans every alias, and a rebuilt session
     * holds an alias per restored fact, so a snapshot of 11,000 facts took 6 s instead of 0.3 s.
     */
    Map<Long, java.util.List<String>> allKeys() {
        Map<Entry, java.util.List<String>> byEntry = new java.util.IdentityHashMap<Entry, java.util.List<String>>();
        for (Map.Entry<String, Entry> a : aliases.entrySet()) {
            byEntry.computeIfAbsent(a.getValue(), x -> new java.util.ArrayList<String>()).add(a.getKey());
        }
        Map<Long, java.util.List<String>> out = new HashMap<Long, java.util.List<String>>();
        for (Map.Entry<Long, Entry> e : byId.entrySet()) {
            java.util.List<String> keys = new java.util.ArrayList<String>();
            for (Integer hash : e.getValue().hashes) keys.add(e.getKey() + ":" + hash);
            java.util.List<String> more = byEntry.get(e.getValue());
            if (more != null) keys.addAll(more);
            out.put(e.getKey(), keys);
        }
        return out;
    }
}
