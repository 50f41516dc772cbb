package org.printeps.gateway;

import java.io.FileOutputStream;
import java.io.IOException;
import java.util.concurrent.ConcurrentLinkedQueue;
import java.util.concurrent.LinkedBlockingQueue;
import java.util.concurrent.ThreadPoolExecutor;
import java.util.concurrent.TimeUnit;
import java.util.concurrent.atomic.AtomicBoolean;

/**
 * One rule set's stateless fires on JVM threads of its own, their answers handed back to an event
 * loop through an {@link Inbox} (see gateway/engine/bulkhead.py).
 *
 * <p>Why on the JVM side: a Python worker thread must take the GIL to wake up, to call Java and to
 * hand the answer back, each time competing with the event loop that holds it; measured on 2 cores
 * that hand-off cost the REST fire a quarter of its throughput. These threads never touch Python:
 * the loop submits (one JPype call), the fire runs here, and the loop is woken through a pipe and
 * drains every answer that finished meanwhile in one call. Admission control (queue bound, wait
 * estimate) stays with the Python bulkhead, which counts what it submitted; the only check made
 * here is the one that needs the moment a thread takes the fire: a fire that waited longer than
 * {@code maxWaitMs} is answered {@code "waited"} instead of running late.
 */
public final class FireLane {

    /** The answers of every lane for one event loop, and the pipe that wakes it. Thread-safe. */
    public static final class Inbox {
        private final ConcurrentLinkedQueue<String> answers = new ConcurrentLinkedQueue<String>();
        private final AtomicBoolean signalled = new AtomicBoolean();
        private final FileOutputStream wake;

        /** {@code wakePath}: the loop's named pipe, whose read end the loop holds open. */
        public Inbox(String wakePath) throws IOException {
            wake = new FileOutputStream(wakePath);
        }

        void post(String entry) {
            answers.add(entry);
            // one byte per drain: an answer added while the loop has not drained yet joins that drain
            if (signalled.compareAndSet(false, true)) {
                try {
                    wake.write(1);
                } catch (IOException gone) {
                    // the loop closed its pipe: nobody is waiting for the answer any more
                }
            }
        }

        /** Every answer posted so far, as one JSON array of {@code [ticket, elapsedNs, answer]}
         *  (elapsedNs -1: refused for waiting too long). Cleared before it is read: an answer
         *  posted from now on writes the next wake-up byte. */
        public String drain() {
            signalled.set(false);
            StringBuilder b = new StringBuilder(512).append('[');
            String entry;
            boolean first = true;
            while ((entry = answers.poll()) != null) {
                if (!first) b.append(',');
                b.append(entry);
                first = false;
            }
            return b.append(']').toString();
        }

        public void close() {
            try {
                wake.close();
            } catch (IOException ignored) {
                // already closed
            }
        }
    }

    /** An answer's elapsed time when its fire was refused for waiting too long (bulkhead.WAITED). */
    static final long WAITED = -1L;

    private final ThreadPoolExecutor pool;

    /** {@code workers} threads named {@code fire-<name>}, started on demand and gone after {@code idleMs}. */
    public FireLane(String name, int workers, long idleMs) {
        String threadName = "fire-" + name;
        pool = new ThreadPoolExecutor(workers, workers, idleMs, TimeUnit.MILLISECONDS, new LinkedBlockingQueue<Runnable>(),
                task -> {
                    Thread t = new Thread(task, threadName);
                    t.setDaemon(true);
                    return t;
                });
        pool.allowCoreThreadTimeOut(true);
    }

    /** Fires {@code factsJson} on {@code runner} (as {@link Runner#fire}) on one of this lane's
     *  threads; the answer goes to {@code inbox} under {@code ticket}. */
    public void fire(Inbox inbox, long ticket, Runner runner, String factsJson, int limit, boolean returnFacts,
                     boolean recordFacts, long timeoutMs, long maxWaitMs) {
        long queued = System.nanoTime();
        pool.execute(() -> {
            long started = System.nanoTime();
            if (maxWaitMs > 0 && started - queued > maxWaitMs * 1_000_000L) {
                inbox.post("[" + ticket + "," + WAITED + "," + (started - queued) + "]");
                return;
            }
            String answer;
            try {
                answer = runner.fire(factsJson, limit, returnFacts, recordFacts, timeoutMs);
            } catch (Throwable t) {  // handed to the caller as the fire's error, whatever it is
                answer = Runner.runtimeError(null, Runner.rootMessage(t));
            }
            inbox.post("[" + ticket + "," + (System.nanoTime() - started) + "," + answer + "]");
        });
    }

    /** {@link #fire} for several fires at once (one JVM call from the event loop for the fires of one
     *  loop iteration): {@code tickets[i]} is answered for {@code runners[i]} on {@code facts[i]}. */
    public void fireMany(Inbox inbox, long[] tickets, Runner[] runners, String[] facts, int limit, boolean returnFacts,
                         boolean recordFacts, long timeoutMs, long maxWaitMs) {
        for (int i = 0; i < tickets.length; i++) {
            fire(inbox, tickets[i], runners[i], facts[i], limit, returnFacts, recordFacts, timeoutMs, maxWaitMs);
        }
    }

    /** This lane's live threads, for the bulkhead's stats. */
    public int threads() {
        return pool.getPoolSize();
    }

    public void shutdown() {
        pool.shutdown();
    }
}
