package org.slf4j.impl;

import org.slf4j.ILoggerFactory;
import org.slf4j.spi.LoggerFactoryBinder;

/**
 * SLF4J 1.7 binding for the embedded JVM: Drools' log lines at WARN and ERROR go to stderr with a
 * "[java]" prefix; everything below is dropped. Without a binding SLF4J prints three lines of
 * complaint at every start and drops warnings that matter.
 */
public final class StaticLoggerBinder implements LoggerFactoryBinder {
    private static final StaticLoggerBinder SINGLETON = new StaticLoggerBinder();
    public static String REQUESTED_API_VERSION = "1.6.99";
    private final ILoggerFactory factory = new org.printeps.gateway.QuietLoggerFactory();

    public static StaticLoggerBinder getSingleton() { return SINGLETON; }

    public ILoggerFactory getLoggerFactory() { return factory; }

    public String getLoggerFactoryClassStr() { return org.printeps.gateway.QuietLoggerFactory.class.getName(); }
}
