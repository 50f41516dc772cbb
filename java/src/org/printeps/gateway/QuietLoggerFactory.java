package org.printeps.gateway;

import java.util.concurrent.ConcurrentHashMap;

import org.slf4j.ILoggerFactory;
import org.slf4j.Logger;
import org.slf4j.helpers.FormattingTuple;
import org.slf4j.helpers.MarkerIgnoringBase;
import org.slf4j.helpers.MessageFormatter;

/** Loggers that print WARN and ERROR to stderr and drop the rest (see StaticLoggerBinder). */
public final class QuietLoggerFactory implements ILoggerFactory {
    private final ConcurrentHashMap<String, Logger> loggers = new ConcurrentHashMap<String, Logger>();

    public Logger getLogger(String name) {
        Logger l = loggers.get(name);
        if (l == null) {
            l = new QuietLogger(name);
            Logger prev = loggers.putIfAbsent(name, l);
            if (prev != null) l = prev;
        }
        return l;
    }

    static final class QuietLogger extends MarkerIgnoringBase {
        private static final long serialVersionUID = 1L;

        QuietLogger(String name) { this.name = name; }

        private void print(String level, FormattingTuple t) {
            String shortName = name.substring(name.lastIndexOf('.') + 1);
            String message = String.valueOf(t.getMessage());
            String[] lines = message.split("\n", 4);  // Drools puts whole stack traces into some messages
            if (lines.length > 3) message = lines[0] + "\n" + lines[1] + "\n" + lines[2] + "\n  ...";
            System.err.println("[java] " + level + " " + shortName + ": " + message);
            if (t.getThrowable() != null) System.err.println("[java]   caused by " + t.getThrowable());
        }

        public boolean isTraceEnabled() { return false; }
        public void trace(String msg) { }
        public void trace(String f, Object a) { }
        public void trace(String f, Object a, Object b) { }
        public void trace(String f, Object... a) { }
        public void trace(String msg, Throwable t) { }
        public boolean isDebugEnabled() { return false; }
        public void debug(String msg) { }
        public void debug(String f, Object a) { }
        public void debug(String f, Object a, Object b) { }
        public void debug(String f, Object... a) { }
        public void debug(String msg, Throwable t) { }
        public boolean isInfoEnabled() { return false; }
        public void info(String msg) { }
        public void info(String f, Object a) { }
        public void info(String f, Object a, Object b) { }
        public void info(String f, Object... a) { }
        public void info(String msg, Throwable t) { }
        public boolean isWarnEnabled() { return true; }
        public void warn(String msg) { print("WARN", new FormattingTuple(msg)); }
        public void warn(String f, Object a) { print("WARN", MessageFormatter.format(f, a)); }
        public void warn(String f, Object a, Object b) { print("WARN", MessageFormatter.format(f, a, b)); }
        public void warn(String f, Object... a) { print("WARN", MessageFormatter.arrayFormat(f, a)); }
        public void warn(String msg, Throwable t) { print("WARN", new FormattingTuple(msg, null, t)); }
        public boolean isErrorEnabled() { return true; }
        public void error(String msg) { print("ERROR", new FormattingTuple(msg)); }
        public void error(String f, Object a) { print("ERROR", MessageFormatter.format(f, a)); }
        public void error(String f, Object a, Object b) { print("ERROR", MessageFormatter.format(f, a, b)); }
        public void error(String f, Object... a) { print("ERROR", MessageFormatter.arrayFormat(f, a)); }
        public void error(String msg, Throwable t) { print("ERROR", new FormattingTuple(msg, null, t)); }
    }
}
