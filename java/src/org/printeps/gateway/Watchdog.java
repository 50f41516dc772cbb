package org.printeps.gateway;

import java.util.Set;
import java.util.concurrent.ConcurrentHashMap;

import org.kie.api.runtime.KieSession;

/**
 * Halts fires that run past their time limit ({@code engine.fire_timeout_s}), through the public
 * {@link KieSession#halt()}: the fire stops before its next rule firing.
 *
 * Why one polling thread instead of a timer per fire: a fire takes well under a millisecond, and
 * scheduling (then cancelling) a timer task per fire wakes the timer thread each time a new earliest
 * deadline arrives. Here a fire only adds itself to a set and removes itself again (~100 ns), and
 * one daemon thread looks at the set every {@link #PERIOD_MS} ms. The limit is therefore kept to
 * within that period. A then-part that never returns (one consequence looping forever) is not
 * stopped: {@code halt()} acts between firings.
 */
final class Watchdog {
    static final long PERIOD_MS = 20;

    /** One fire being watched; {@code halted} says its time ran out and it was halted. */
    static final class Watch {
        final KieSession session;
        final long deadline;
        volatile boolean halted;

        Watch(KieSession session, long deadline) {
            this.session = session;
            this.deadline = deadline;
        }
    }

    private static final Set<Watch> RUNNING = ConcurrentHashMap.newKeySet();
    private static Thread thread;

    private Watchdog() {}

    /** Watches a fire of {@code session} that may run {@code timeoutMs} (null when 0: not watched). */
    static Watch watch(KieSession session, long timeoutMs) {
        if (timeoutMs <= 0) return null;
        Watch w = new Watch(session, System.nanoTime() + timeoutMs * 1_000_000L);
        RUNNING.add(w);
        ensureStarted();
        return w;
    }

    static void release(Watch w) {
        if (w != null) RUNNING.remove(w);
    }

    private static synchronized void ensureStarted() {
        if (thread != null) return;
        thread = new Thread(Watchdog::loop, "printeps-fire-watchdog");
        thread.setDaemon(true);
        thread.start();
    }

    private static void loop() {
        while (true) {
            try {
                Thread.sleep(PERIOD_MS);
            } catch (InterruptedException e) {
                return;
            }
            long now = System.nanoTime();
            for (Watch w : RUNNING) {
                if (!w.halted && now - w.deadline >= 0) {
                    w.halted = true;
                    try {
                        w.session.halt();
                    } catch (RuntimeException e) {
                        // a session disposed meanwhile: its fire is over anyway
                    }
                }
            }
        }
    }
}
