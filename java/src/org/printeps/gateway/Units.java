package org.printeps.gateway;

import java.io.ByteArrayInputStream;
import java.io.ByteArrayOutputStream;
import java.io.IOException;
import java.io.InputStream;
import java.net.MalformedURLException;
import java.net.URL;
import java.net.URLConnection;
import java.net.URLStreamHandler;
import java.util.ArrayList;
import java.util.HashMap;
import java.util.LinkedHashMap;
import java.util.List;
import java.util.Map;
import java.util.zip.ZipEntry;
import java.util.zip.ZipInputStream;
import java.util.zip.ZipOutputStream;

import org.drools.model.EntryPoint;
import org.drools.model.Global;
import org.drools.model.Model;
import org.drools.model.Query;
import org.drools.model.Rule;
import org.drools.model.TypeMetaData;
import org.kie.api.KieBase;
import org.kie.api.KieBaseConfiguration;
import org.kie.api.builder.KieModule;

/**
 * Compilation units of the executable model: their generated classes kept as bytes, loaded again
 * without recompiling, and one KieBase assembled from the rules of many units.
 *
 * Why: Drools' executable model turns DRL into Java classes (a {@code Rules<uuid>} model class per
 * package, lambda, metadata and declared-type classes) and compiling them is nearly all of a build;
 * building the Rete network from ready model objects is cheap. So the gateway compiles a rule set
 * in units, caches each unit's class bytes by content, and a new version compiles only the rules
 * that changed, then assembles one KieBase from the rules of all units.
 *
 * Every unit has a class loader of its own (units may generate classes of the same name) whose
 * parent is the loader of the declarations unit, so all rules see the same declared classes.
 */
public final class Units {
    private Units() {}

    /** A class loader over generated class bytes (binary name -> bytes), parent first. */
    public static final class UnitClassLoader extends ClassLoader {
        private volatile Map<String, byte[]> classes;

        UnitClassLoader(ClassLoader parent, Map<String, byte[]> classes) {
            super(parent);
            this.classes = classes;
        }

        @Override
        protected Class<?> findClass(String name) throws ClassNotFoundException {
            Map<String, byte[]> map = classes;
            byte[] bytes = map == null ? null : map.get(name);
            if (bytes == null) throw new ClassNotFoundException(name);
            return defineClass(name, bytes, 0, bytes.length);
        }

        /**
         * The class bytes as resources too: Drools' Java compiler reads the classes a unit depends
         * on this way (through the builder's own loader, whose parent this is), so rule units
         * compile against the declared types of the declarations unit.
         */
        @Override
        protected URL findResource(String name) {
            Map<String, byte[]> map = classes;
            if (map == null || !name.endsWith(".class")) return null;
            final byte[] bytes = map.get(binaryName(name));
            if (bytes == null) return null;
            try {
                return new URL(null, "printeps-unit:/" + name, new URLStreamHandler() {
                    @Override
                    protected URLConnection openConnection(URL u) {
                        return new URLConnection(u) {
                            @Override public void connect() {}
                            @Override public InputStream getInputStream() { return new ByteArrayInputStream(bytes); }
                        };
                    }
                });
            } catch (MalformedURLException e) {
                return null;
            }
        }

        /** Defines every class now, so a broken unit fails here and not at its first fire. */
        public int loadAll() throws ClassNotFoundException {
            Map<String, byte[]> map = classes;
            if (map == null) return 0;
            for (String name : map.keySet()) loadClass(name);
            return map.size();
        }

        /** Drops the bytes once every class is defined (rule units: nothing compiles against them). */
        public void release() { classes = null; }
    }

    /** A loader for {@code classes} (keys: binary names or {@code a/b/C.class} paths). */
    public static UnitClassLoader loader(ClassLoader parent, Map<String, byte[]> classes) {
        Map<String, byte[]> byName = new HashMap<String, byte[]>(classes.size() * 2);
        for (Map.Entry<String, byte[]> e : classes.entrySet()) byName.put(binaryName(e.getKey()), e.getValue());
        return new UnitClassLoader(parent == null ? Units.class.getClassLoader() : parent, byName);
    }

    static String binaryName(String key) {
        if (key.endsWith(".class")) key = key.substring(0, key.length() - 6);
        return key.replace('/', '.');
    }

    // ------------------------------------------------------------------ what a build produced

    /** The generated classes of a built KieModule (binary name -> bytes). */
    public static Map<String, byte[]> classesOf(KieModule module) {
        Map<String, byte[]> out = new HashMap<String, byte[]>();
        for (String file : DroolsInternals.moduleFileNames(module)) {
            if (file.endsWith(".class")) out.put(binaryName(file), DroolsInternals.moduleFile(module, file));
        }
        return out;
    }

    /** The executable-model classes ({@code Rules<uuid>}, one per package) a KieModule lists. */
    public static String[] modelClassNames(KieModule module) {
        return DroolsInternals.modelClassNames(module);
    }

    /** Class bytes as one zip (what the disk cache and exported rule sets hold). */
    public static byte[] zip(Map<String, byte[]> classes) throws IOException {
        ByteArrayOutputStream bytes = new ByteArrayOutputStream(64 * 1024);
        try (ZipOutputStream zip = new ZipOutputStream(bytes)) {
            zip.setLevel(1);  // fast: the cache is written on the deploy path
            for (Map.Entry<String, byte[]> e : classes.entrySet()) {
                zip.putNextEntry(new ZipEntry(e.getKey().replace('.', '/') + ".class"));
                zip.write(e.getValue());
                zip.closeEntry();
            }
        }
        return bytes.toByteArray();
    }

    /** The classes of a zip written by {@link #zip}. */
    public static Map<String, byte[]> unzip(byte[] data) throws IOException {
        Map<String, byte[]> out = new HashMap<String, byte[]>();
        try (ZipInputStream zip = new ZipInputStream(new ByteArrayInputStream(data))) {
            ZipEntry entry;
            byte[] buffer = new byte[16 * 1024];
            while ((entry = zip.getNextEntry()) != null) {
                ByteArrayOutputStream one = new ByteArrayOutputStream();
                int n;
                while ((n = zip.read(buffer)) > 0) one.write(buffer, 0, n);
                out.put(binaryName(entry.getName()), one.toByteArray());
            }
        }
        return out;
    }

    // ------------------------------------------------------------------ models and assembly

    /** The executable-model classes of a unit, instantiated (each implements {@link Model}). */
    public static List<Model> models(ClassLoader loader, String[] modelClassNames) throws Exception {
        List<Model> out = new ArrayList<Model>();
        for (String name : modelClassNames) {
            Class<?> cls = Class.forName(name, true, loader);
            out.add((Model) cls.getDeclaredConstructor().newInstance());
        }
        return out;
    }

    /**
     * One KieBase from the declarations of {@code declarations} (declared types, globals, queries,
     * entry points) and rules picked from {@code units}, in the given order: rule k is
     * {@code ruleNames[k]} of package {@code packages[k]} in the models of {@code units.get(unitIndex[k])}.
     *
     * The order matters: at equal salience Drools fires rules in load order, which is their order
     * in the package's model; one merged model per package gives every build of the same text the
     * same order, however it was split into units.
     */
    public static KieBase assemble(List<Model> declarations, List<List<Model>> units, int[] unitIndex,
                                   String[] packages, String[] ruleNames, KieBaseConfiguration conf) {
        Map<String, MergedModel> merged = new LinkedHashMap<String, MergedModel>();
        for (Model m : declarations) {
            MergedModel into = merged.computeIfAbsent(m.getPackageName(), MergedModel::new);
            into.addDeclarations(m);
        }
        List<Map<String, Map<String, Object>>> index = new ArrayList<Map<String, Map<String, Object>>>();
        for (int u = 0; u < units.size(); u++) index.add(null);
        for (int k = 0; k < ruleNames.length; k++) {
            int u = unitIndex[k];
            Map<String, Map<String, Object>> byPackage = index.get(u);
            if (byPackage == null) {  // a unit's rules, and the queries built apart from the declarations
                byPackage = new HashMap<String, Map<String, Object>>();
                for (Model m : units.get(u)) {
                    Map<String, Object> items = byPackage.computeIfAbsent(m.getPackageName(), p -> new HashMap<String, Object>());
                    for (Query q : m.getQueries()) items.put(q.getName(), q);
                    for (Rule r : m.getRules()) items.put(r.getName(), r);
                    MergedModel into = merged.computeIfAbsent(m.getPackageName(), MergedModel::new);
                    into.addEntryPoints(m);
                }
                index.set(u, byPackage);
            }
            Map<String, Object> items = byPackage.get(packages[k]);
            Object item = items == null ? null : items.get(ruleNames[k]);
            if (item == null) {
                throw new IllegalStateException("unit " + u + " has no rule '" + ruleNames[k] + "' in package " + packages[k]);
            }
            MergedModel into = merged.computeIfAbsent(packages[k], MergedModel::new);
            if (item instanceof Rule) into.rules.add((Rule) item);
            else into.queries.add((Query) item);
        }
        return DroolsInternals.kieBaseFromModels(new ArrayList<Model>(merged.values()), conf);
    }

    /** One KieBase from whole models as they are (a rule set compiled as one unit, without a rule order). */
    public static KieBase build(List<Model> models, KieBaseConfiguration conf) {
        return DroolsInternals.kieBaseFromModels(models, conf);
    }

    /** All of one package: declarations from the declarations unit, rules from wherever they were compiled. */
    static final class MergedModel implements Model {
        private final String packageName;
        final List<Rule> rules = new ArrayList<Rule>();
        private final Map<String, Global> globals = new LinkedHashMap<String, Global>();
        private final List<Query> queries = new ArrayList<Query>();
        private final List<TypeMetaData> types = new ArrayList<TypeMetaData>();
        private final Map<String, EntryPoint> entryPoints = new LinkedHashMap<String, EntryPoint>();

        MergedModel(String packageName) { this.packageName = packageName; }

        void addDeclarations(Model m) {
            for (Global g : m.getGlobals()) globals.putIfAbsent(g.getName(), g);
            queries.addAll(m.getQueries());
            types.addAll(m.getTypeMetaDatas());
            addEntryPoints(m);
        }

        void addEntryPoints(Model m) {
            for (EntryPoint e : m.getEntryPoints()) entryPoints.putIfAbsent(e.getName(), e);
        }

        public String getName() { return packageName + ".merged"; }
        public String getPackageName() { return packageName; }
        public List<Global> getGlobals() { return new ArrayList<Global>(globals.values()); }
        public List<Rule> getRules() { return rules; }
        public List<Query> getQueries() { return queries; }
        public List<TypeMetaData> getTypeMetaDatas() { return types; }
        public List<EntryPoint> getEntryPoints() { return new ArrayList<EntryPoint>(entryPoints.values()); }
    }

    // ------------------------------------------------------------------ what a DRL text holds

    /**
     * The top-level items of a parsed DRL text, as one JSON string (one JVM crossing per file):
     * {@code {"package": name, "unit": bool, "items": [[kind, name, start, end, line, parent], ...]}}
     * with kind one of rule, query, type, enum, function, window, entrypoint; start/end are the
     * parser's character offsets (refined on the Python side), parent the rule a rule extends.
     */
    public static String describe(Object packageDescr) {
        return DroolsInternals.drlItems(packageDescr);
    }

    /** Drools' version, part of the cache key: generated classes are only valid for the Drools that made them. */
    public static String droolsVersion() {
        return DroolsInternals.droolsVersion();
    }
}
