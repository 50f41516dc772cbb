package org.printeps.gateway;

import java.time.LocalDate;
import java.time.ZoneId;
import java.time.format.DateTimeFormatter;
import java.time.format.DateTimeFormatterBuilder;
import java.util.Calendar;
import java.util.GregorianCalendar;
import java.util.Locale;
import java.util.function.Supplier;

/**
 * The Drools implementation classes {@link PlainRules} needs beyond the executable model's API, in
 * small static methods: the accumulate functions the executable model's generated code constructs,
 * and the date format it parses {@code date-effective}/{@code date-expires} with.
 *
 * Why a file of its own: implementation classes change between Drools versions; keeping every use
 * of them in one place (to be folded into DroolsInternals) keeps an upgrade's work in one file.
 */
final class PlainRulesInternals {
    private PlainRulesInternals() {}

    /**
     * The accumulate function the executable model uses for {@code name} over a value of
     * {@code input} (boxed), or null when its choice is not known here: {@code count} of anything,
     * {@code sum}/{@code min}/{@code max} of doubles ({@code Sum}, {@code NumericMin},
     * {@code NumericMax}; other input types get other functions, left to the compiler).
     */
    static Supplier<?> accumulateFunction(String name, Class<?> input) {
        switch (name) {
            case "count": return org.drools.core.base.accumulators.CountAccumulateFunction::new;
            case "sum": return input == Double.class ? org.drools.core.base.accumulators.SumAccumulateFunction::new : null;
            case "min": return input == Double.class ? org.drools.core.base.accumulators.NumericMinAccumulateFunction::new : null;
            case "max": return input == Double.class ? org.drools.core.base.accumulators.NumericMaxAccumulateFunction::new : null;
            default: return null;
        }
    }

    /** The type the executable model declares the result of {@link #accumulateFunction} with. */
    static Class<?> accumulateResultType(String name) {
        switch (name) {
            case "count": return Long.class;
            case "sum": return Double.class;
            default: return Number.class;
        }
    }

    private static volatile DateTimeFormatter dates;

    /**
     * A {@code date-effective}/{@code date-expires} value as the executable model's generated code
     * computes it: the day in Drools' date format ({@code drools.dateformat}, English,
     * case-insensitive) at the start of the day in the JVM's zone.
     */
    static Calendar ruleDate(String text) {
        DateTimeFormatter f = dates;
        if (f == null) {
            f = new DateTimeFormatterBuilder().parseCaseInsensitive()
                    .appendPattern(org.drools.util.DateUtils.getDateFormatMask()).toFormatter(Locale.ENGLISH);
            dates = f;
        }
        return GregorianCalendar.from(LocalDate.parse(text, f).atStartOfDay(ZoneId.systemDefault()));
    }
}
