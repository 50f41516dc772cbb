package org.printeps.gateway;

import java.time.LocalDate;
import java.time.ZoneId;
import java.util.ArrayList;
import java.util.Collections;
import java.util.HashMap;
import java.util.LinkedHashMap;
import java.util.List;
import java.util.Map;

import org.drools.model.DomainClassMetadata;
import org.drools.model.EntryPoint;
import org.drools.model.Global;
import org.drools.model.Model;
import org.drools.model.Query;
import org.drools.model.Rule;
import org.drools.model.TypeMetaData;

import static org.printeps.gateway.PlainValues.*;

/**
 * Rules of the plain shapes built at run time as executable-model objects, without generating or
 * compiling Java. The rule set's Python side ({@code gateway.engine.plain_rules}) describes each
 * such rule: patterns on declared or imported types with field-versus-literal and
 * field-versus-bound-field comparisons, in/matches, not/exists, count/sum/min/max accumulates, the
 * usual rule attributes (format 2), a then-part of calls on one global with
 * literals, bound facts, their getters, text joined from those and static calls of the rule
 * policy's {@code java.lang} classes (format 3). This class builds the same
 * {@link Rule} the executable model's generated code builds: the same alpha and beta indexes,
 * property reactivity, accumulate function and constraint ids, so Drools hashes, shares and fires
 * them alike, also next to compiled rules.
 *
 * Why: generating and compiling Java costs ~11 ms of CPU per rule (10,000 rules: two minutes of
 * CPU); building the same model objects takes microseconds. A rule this class cannot build exactly
 * (an unknown field, a type it would have to convert, an ambiguous method) is reported as rejected
 * with the reason and goes through Drools' compiler, which also reports its errors with file, line
 * and column.
 */
public final class PlainRules {
    private PlainRules() {}

    /** The description format this class reads (the Python side writes the same number); format 2
     *  (cached units of before static calls) is a subset of it and still read. */
    public static final int FORMAT = 3;

    /** What {@link #build} made: one model per package, and the rules it refused ("index\treason"). */
    public static final class Built {
        private final List<Model> models;
        private final List<String> rejected;

        Built(List<Model> models, List<String> rejected) {
            this.models = models;
            this.rejected = rejected;
        }

        public List<Model> models() { return models; }
        public String[] rejected() { return rejected.toArray(new String[0]); }
    }

    /** A rule this class cannot build exactly as the compiler would. */
    static final class Reject extends RuntimeException {
        Reject(String message) { super(message, null, false, false); }
    }

    /**
     * Builds the rules of {@code spec} (JSON: {@code {"format": 3, "rules": [...]}}) against the
     * classes of {@code loader} (the declarations unit's) and the globals of {@code declarations}.
     */
    public static Built build(ClassLoader loader, List<Model> declarations, String spec) {
        return build(loader, declarations, spec, false);
    }

    /**
     * {@link #build(ClassLoader, List, String)}, for a request-join network when {@code requestJoins}:
     * every pattern after a rule's first reads the request's facts ({@link RequestFacts}) instead of
     * a memory of every fact of its type. Only {@link Runner#fire} may fire such rules (it opens the
     * request's facts); any other session would find nothing to join.
     */
    @SuppressWarnings("unchecked")
    public static Built build(ClassLoader loader, List<Model> declarations, String spec, boolean requestJoins) {
        Map<String, Object> root = (Map<String, Object>) Json.parse(spec);
        Object format = root.get("format");
        if (!(format instanceof Number) || ((Number) format).intValue() < 2 || ((Number) format).intValue() > FORMAT) {
            throw new IllegalArgumentException("plain rule description of format " + format + ", expected " + FORMAT);
        }
        Map<String, Global<?>> globals = new HashMap<String, Global<?>>();
        for (Model m : declarations) {
            for (Global<?> g : m.getGlobals()) globals.putIfAbsent(m.getPackageName() + "\0" + g.getName(), g);
        }
        Map<String, PlainModel> byPackage = new LinkedHashMap<String, PlainModel>();
        List<String> rejected = new ArrayList<String>();
        List<Object> rules = (List<Object>) root.get("rules");
        Context context = new Context(loader, globals, requestJoins);
        for (int k = 0; k < rules.size(); k++) {
            Map<String, Object> r = (Map<String, Object>) rules.get(k);
            try {
                PlainModel model = byPackage.computeIfAbsent((String) r.get("package"), PlainModel::new);
                if (Boolean.TRUE.equals(r.get("query"))) {
                    model.queries.add(new PlainRule(context.forQueries(), r).buildQuery());
                } else {
                    model.rules.add(new PlainRule(context, r).build());
                }
            } catch (Reject e) {
                rejected.add(k + "\t" + e.getMessage());
            } catch (RuntimeException | LinkageError e) {
                rejected.add(k + "\t" + e);
            }
        }
        return new Built(new ArrayList<Model>(byPackage.values()), rejected);
    }

    /**
     * How a plain rule reads {@code getter} (its constraints, bindings, indexes and then-parts): a
     * generated function that calls it directly, or reflection where none can be made (see
     * {@link PlainValues#reader}). Public for the tests, which check both and what they return.
     */
    public static java.util.function.Function<Object, Object> reader(java.lang.reflect.Method getter) {
        return PlainValues.reader(getter);
    }

    /** Whether {@link #reader} calls {@code getter} directly (false: through {@code Method.invoke}). */
    public static boolean readsDirectly(java.lang.reflect.Method getter) {
        return PlainValues.readsDirectly(getter);
    }

    // ------------------------------------------------------------------ shared state of one build

    static final class Context {
        final ClassLoader loader;
        final Map<String, Global<?>> globals;
        final Map<Class<?>, DomainClassMetadata> metadata;
        final Map<String, Property> properties;
        /** Whether the patterns after a rule's first read the request's facts (see {@link PlainRule}). */
        final boolean requestJoins;

        Context(ClassLoader loader, Map<String, Global<?>> globals, boolean requestJoins) {
            this.loader = loader;
            this.globals = globals;
            this.metadata = new HashMap<Class<?>, DomainClassMetadata>();
            this.properties = new HashMap<String, Property>();
            this.requestJoins = requestJoins;
        }

        /** The same build's caches (metadata, field readers), for the patterns of its queries. */
        private Context(Context build) {
            this.loader = build.loader;
            this.globals = build.globals;
            this.metadata = build.metadata;
            this.properties = build.properties;
            this.requestJoins = false;
        }

        private Context queries;

        /** This build's context for queries: they always read the session's memories (a query is
         *  asked of a session, never of a request), sharing this build's metadata and field readers. */
        Context forQueries() {
            if (!requestJoins) return this;
            if (queries == null) queries = new Context(this);
            return queries;
        }

        DomainClassMetadata metadata(Class<?> type) {
            return metadata.computeIfAbsent(type, DroolsInternals::domainClassMetadata);
        }

        Property property(Class<?> type, String field) {
            return properties.computeIfAbsent(type.getName() + "\0" + field, key -> Property.of(type, field, metadata(type)));
        }
    }

    // ------------------------------------------------------------------ rule dates

    /**
     * Why {@code text} is not a date {@code date-effective}/{@code date-expires} take, or null if it
     * is one: parsed as the executable model's generated code parses it (the
     * {@code drools.dateformat} mask, English month names, any case). Why: the compiled path fails
     * on a bad date only when the built unit is loaded, with a bare InvocationTargetException; the
     * gateway checks every such attribute before building, and says where and what is expected.
     */
    public static String ruleDateProblem(String text) {
        try {
            DroolsInternals.ruleDate(text);
            return null;
        } catch (RuntimeException e) {
            return "'" + text + "' is not a date of the form " + ruleDateFormat() + " (e.g. "
                    + DroolsInternals.ruleDateExample() + ")";
        }
    }

    /**
     * The day a {@code date-effective}/{@code date-expires} value means, as {@code yyyy-MM-dd}, or
     * null if it is not a date: read as {@link #ruleDateProblem} reads it, so an explanation judges
     * the date with the mask the rule base was built with ({@code drools.dateformat}).
     */
    public static String ruleDay(String text) {
        try {
            return LocalDate.ofInstant(DroolsInternals.ruleDate(text).toInstant(), ZoneId.systemDefault()).toString();
        } catch (RuntimeException e) {
            return null;
        }
    }

    /** The date mask {@code date-effective}/{@code date-expires} values are read with. */
    public static String ruleDateFormat() {
        return DroolsInternals.ruleDateFormat();
    }

    /** The rules of one package that were built here (no declarations: those come from the declarations unit). */
    static final class PlainModel implements Model {
        private final String packageName;
        final List<Rule> rules = new ArrayList<Rule>();
        final List<Query> queries = new ArrayList<Query>();

        PlainModel(String packageName) { this.packageName = packageName; }

        public String getName() { return packageName + ".plain"; }
        public String getPackageName() { return packageName; }
        public List<Global> getGlobals() { return Collections.emptyList(); }
        public List<Rule> getRules() { return rules; }
        public List<Query> getQueries() { return queries; }
        public List<TypeMetaData> getTypeMetaDatas() { return Collections.emptyList(); }
        public List<EntryPoint> getEntryPoints() { return Collections.emptyList(); }
    }
}