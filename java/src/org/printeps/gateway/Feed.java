package org.printeps.gateway;

import java.nio.ByteBuffer;
import java.nio.ByteOrder;
import java.nio.charset.StandardCharsets;
import java.util.ArrayDeque;
import java.util.concurrent.ConcurrentLinkedQueue;
import java.util.concurrent.TimeUnit;
import java.util.concurrent.locks.LockSupport;

/**
 * A pipelined event feed into one {@link Session}: a worker thread inserts and fires each submitted
 * event on its own, in order (exactly what {@link Session#pushAt} does for one event), and keeps
 * each event's answer until the caller collects it with {@link #poll}.
 *
 * Why: on the synchronous path the caller's thread does its own work (encode, decode, react) and
 * the Drools work one after the other, and pays one JPype crossing per event. Here the Drools work
 * runs on its own thread while the caller prepares the next events and handles earlier answers;
 * events gathered by the caller cross over together ({@link #submitBatch}), and so do answers.
 * The caller bounds the events in flight (gateway/engine/feed.py): nothing here blocks a submit,
 * so a caller holding its own locks cannot deadlock with the worker.
 *
 * Input buffer layout for {@link #submitBatch}: per event a little-endian int32 byte length, an
 * int64 timestamp (Long.MIN_VALUE: do not move the clock), then the UTF-8 JSON list of its facts.
 */
public final class Feed {
    private static final class Item {
        final String facts;
        final long timestampMs;
        Item(String facts, long timestampMs) { this.facts = facts; this.timestampMs = timestampMs; }
    }

    private static final Item STOP = new Item(null, 0L);
    /** poll(): nothing arrived within the timeout. */
    public static final int NONE = 0;
    /** poll(): the next answer is larger than the output buffer; {@link #takeOverflow} has it. */
    public static final int OVERFLOW = -1;
    /** poll(): the feed is closed and every answer was collected. */
    public static final int FINISHED = -2;

    private final Session session;
    private final int limit;
    private final boolean returnFacts;
    private final ConcurrentLinkedQueue<Item> pending = new ConcurrentLinkedQueue<Item>();
    private final ArrayDeque<byte[]> answers = new ArrayDeque<byte[]>();  // guarded by itself
    private final ByteBuffer in;
    private final ByteBuffer out;
    private final Thread worker;
    private volatile boolean workerParked;
    private volatile boolean closing;
    private volatile boolean aborted;
    private boolean finished;  // guarded by answers
    private long oldestNanos;  // when the oldest uncollected answer was written; guarded by answers
    private String overflow;   // guarded by answers

    public Feed(Session session, int limit, boolean returnFacts, ByteBuffer in, ByteBuffer out) {
        this.session = session;
        this.limit = limit;
        this.returnFacts = returnFacts;
        this.in = in.duplicate().order(ByteOrder.LITTLE_ENDIAN);
        this.out = out;
        this.worker = new Thread(this::work, "printeps-feed");
        this.worker.setDaemon(true);
        this.worker.start();
    }

    /**
     * Submits the {@code count} events laid out in the input buffer (see the class comment).
     * Returns how many answers are waiting to be collected (so the caller can collect them now).
     */
    public int submitBatch(int count) {
        int pos = 0;
        for (int k = 0; k < count; k++) {
            int length = in.getInt(pos);
            long timestampMs = in.getLong(pos + 4);
            byte[] bytes = new byte[length];
            in.get(pos + 12, bytes, 0, length);
            pos += 12 + length;
            enqueue(new Item(new String(bytes, StandardCharsets.UTF_8), timestampMs));
        }
        wakeWorker();
        synchronized (answers) {
            return answers.size();
        }
    }

    /** Submits one event given as text (for events larger than the input buffer). */
    public void submitText(String factsJson, long timestampMs) {
        enqueue(new Item(factsJson, timestampMs));
        wakeWorker();
    }

    private void enqueue(Item item) {
        if (closing) throw new IllegalStateException("the feed is closed");
        pending.add(item);
    }

    private void wakeWorker() {
        if (workerParked) LockSupport.unpark(worker);
    }

    private Item next() throws InterruptedException {
        while (true) {
            if (aborted) return STOP;
            Item item = pending.poll();
            if (item != null) return item;
            workerParked = true;
            item = pending.poll();  // re-check: a submit may have missed the flag
            if (item == null && !aborted) LockSupport.park(this);
            workerParked = false;
            if (item != null) return item;
            if (Thread.interrupted()) throw new InterruptedException();
        }
    }

    private void work() {
        try {
            while (true) {
                Item item = next();
                if (item == STOP) break;
                String answer;
                synchronized (session) {  // abort() is called before the session is disposed: checked
                    if (aborted) break;   // under its monitor, no event fires after the dispose
                    try {
                        answer = session.pushAt(item.facts, item.timestampMs, limit, returnFacts);
                    } catch (Throwable t) {  // the answers must stay one per event, in order
                        answer = Runner.runtimeError(null, Runner.rootMessage(t));
                    }
                }
                byte[] bytes = answer.getBytes(StandardCharsets.UTF_8);
                synchronized (answers) {
                    if (answers.isEmpty()) {
                        oldestNanos = System.nanoTime();
                        answers.notifyAll();
                    }
                    answers.add(bytes);
                }
            }
        } catch (InterruptedException e) {
            Thread.currentThread().interrupt();
        } finally {
            synchronized (answers) {
                finished = true;
                answers.notifyAll();
            }
        }
    }

    /**
     * Waits up to {@code timeoutMs} for an answer, then writes as many answers as fit into the
     * output buffer as one JSON list, in submission order. Returns its length, or {@link #NONE},
     * {@link #OVERFLOW}, {@link #FINISHED}.
     */
    public int poll(long timeoutMs) throws InterruptedException {
        synchronized (answers) {
            long deadline = System.nanoTime() + TimeUnit.MILLISECONDS.toNanos(timeoutMs);
            while (answers.isEmpty() && !finished) {
                long left = deadline - System.nanoTime();
                if (left <= 0) return NONE;
                TimeUnit.NANOSECONDS.timedWait(answers, left);
            }
            if (answers.isEmpty()) return FINISHED;
            if (answers.peek().length + 2 > out.capacity()) {
                overflow = "[" + new String(answers.poll(), StandardCharsets.UTF_8) + "]";
                oldestNanos = System.nanoTime();
                return OVERFLOW;
            }
            int pos = 0;
            out.put(pos++, (byte) '[');
            while (!answers.isEmpty()) {
                byte[] a = answers.peek();
                int comma = pos > 1 ? 1 : 0;
                if (pos + comma + a.length + 1 > out.capacity()) break;  // + 1: the closing bracket
                answers.poll();
                if (comma == 1) out.put(pos++, (byte) ',');
                out.put(pos, a, 0, a.length);
                pos += a.length;
            }
            out.put(pos++, (byte) ']');
            oldestNanos = System.nanoTime();  // what is left waits from now
            return pos;
        }
    }

    /**
     * Waits up to {@code timeoutMs} until the oldest uncollected answer has waited
     * {@code lingerMicros} (nobody collected it in time), or the feed finished. True if so.
     */
    public boolean awaitLingering(long lingerMicros, long timeoutMs) throws InterruptedException {
        long linger = TimeUnit.MICROSECONDS.toNanos(lingerMicros);
        synchronized (answers) {
            long deadline = System.nanoTime() + TimeUnit.MILLISECONDS.toNanos(timeoutMs);
            while (!finished) {
                long now = System.nanoTime();
                long left = deadline - now;
                if (!answers.isEmpty()) {
                    long due = oldestNanos + linger - now;
                    if (due <= 0) return true;
                    left = Math.min(left, due);
                }
                if (left <= 0) return false;
                TimeUnit.NANOSECONDS.timedWait(answers, left);
            }
            return true;
        }
    }

    /** The answer (as a one-element JSON list) that {@link #poll} reported as {@link #OVERFLOW}. */
    public String takeOverflow() {
        synchronized (answers) {
            String s = overflow;
            overflow = null;
            return s;
        }
    }

    /** Lets the submitted events finish, then stops the worker (poll then reports FINISHED). */
    public void close() {
        if (closing) return;
        closing = true;
        pending.add(STOP);
        LockSupport.unpark(worker);
    }

    /**
     * Stops after the event being fired: the events not yet fired are dropped (the session is going
     * away); the answers already written can still be collected, then {@link #poll} says FINISHED.
     */
    public void abort() {
        closing = true;
        aborted = true;
        pending.clear();
        LockSupport.unpark(worker);
    }
}
