package org.printeps.gateway;

import java.time.LocalDate;
import java.time.ZoneId;
import java.time.format.DateTimeFormatter;
import java.time.format.DateTimeFormatterBuilder;
import java.util.Calendar;
import java.util.GregorianCalendar;
import java.util.Locale;
import java.util.function.Supplier;
import java.util.ArrayDeque;
import java.util.ArrayList;
import java.util.Collection;
import java.util.Deque;
import java.util.IdentityHashMap;
import java.util.LinkedHashMap;
import java.util.List;
import java.util.Map;

import org.drools.compiler.kie.builder.impl.InternalKieModule;
import org.drools.core.base.ClassObjectType;
import org.drools.core.base.accumulators.SumAccumulateFunction;
import org.drools.core.common.AgendaItem;
import org.drools.core.common.InternalAgenda;
import org.drools.core.common.InternalFactHandle;
import org.drools.core.common.PropagationContext;
import org.drools.core.common.ReteEvaluator;
import org.drools.core.definitions.rule.impl.QueryImpl;
import org.drools.core.definitions.rule.impl.RuleImpl;
import org.drools.core.impl.RuleBase;
import org.drools.core.reteoo.AlphaNode;
import org.drools.core.reteoo.ObjectSink;
import org.drools.core.reteoo.ObjectSource;
import org.drools.core.reteoo.ObjectTypeNode;
import org.drools.core.rule.GroupElement;
import org.drools.core.rule.Pattern;
import org.drools.core.rule.RuleConditionElement;
import org.drools.core.rule.constraint.Constraint;
import org.drools.drl.ast.descr.BaseDescr;
import org.drools.drl.ast.descr.EntryPointDeclarationDescr;
import org.drools.drl.ast.descr.EnumDeclarationDescr;
import org.drools.drl.ast.descr.FunctionDescr;
import org.drools.drl.ast.descr.PackageDescr;
import org.drools.drl.ast.descr.RuleDescr;
import org.drools.drl.ast.descr.TypeDeclarationDescr;
import org.drools.drl.ast.descr.WindowDeclarationDescr;
import org.drools.drl.parser.DrlParser;
import org.drools.drl.parser.lang.dsl.DSLTokenizedMappingFile;
import org.drools.drl.parser.lang.dsl.DefaultExpander;
import org.drools.model.DSL;
import org.drools.model.DomainClassMetadata;
import org.drools.model.Index;
import org.drools.model.Model;
import org.drools.model.Variable;
import org.drools.model.codegen.ExecutableModelProject;
import org.drools.model.functions.accumulate.AccumulateFunction;
import org.drools.modelcompiler.KieBaseBuilder;
import org.drools.modelcompiler.constraints.LambdaConstraint;
import org.drools.modelcompiler.util.ClassUtil;
import org.drools.util.StringUtils;
import org.kie.api.KieBase;
import org.kie.api.KieBaseConfiguration;
import org.kie.api.builder.KieModule;
import org.kie.api.definition.rule.Query;
import org.kie.api.definition.rule.Rule;
import org.kie.api.runtime.KieSession;
import org.kie.api.runtime.rule.FactHandle;
import org.kie.api.runtime.rule.Match;
import org.kie.internal.builder.conf.LanguageLevelOption;

/**
 * The one seam between the gateway and Drools' implementation: every cast to an internal type,
 * every internal class and every formula copied from Drools' code generator lives here. The rest
 * of the Java side uses the public KIE API ({@code org.kie.api}), the executable model's rule DSL
 * ({@code org.drools.model}, the API its generated code is written against) and this class.
 *
 * Why one place: these are assumptions about one Drools version (8.31.1.Final, from the optapy
 * wheel), and some of them break silently: a changed constraint-id formula leaves a rule that
 * never fires, with no error. Each method says which assumption it relies on, and
 * {@code tests/engine/test_drools_seam.py} checks every one of them against the Drools on the
 * classpath, so an upgrade fails there, by name, instead of somewhere in production.
 *
 * On a Drools upgrade: run that test first; a failure names the method below to adapt.
 */
public final class DroolsInternals {
    private DroolsInternals() {}

    /** The Drools version these assumptions were checked against (the seam test pins it). */
    public static final String CHECKED_VERSION = "8.31.1.Final";

    // ------------------------------------------------------------------ version

    /**
     * The Drools version on the classpath, from the manifest of the model compiler's jar (part of
     * the unit cache key: generated classes are only valid for the Drools that made them).
     * Assumes: the drools-model-compiler jar's manifest carries {@code Implementation-Version}.
     */
    public static String droolsVersion() {
        Package p = KieBaseBuilder.class.getPackage();
        String v = p == null ? null : p.getImplementationVersion();
        return v == null ? "unknown" : v;
    }

    // ------------------------------------------------------------------ fact handles

    /**
     * A handle's id (its insertion order within a session). Assumes: every {@link FactHandle} a
     * KIE session hands out is an {@code InternalFactHandle} (DefaultFactHandle, EventFactHandle),
     * whose id is the second field of {@link FactHandle#toExternalForm()}.
     */
    public static long handleId(FactHandle h) {
        return ((InternalFactHandle) h).getId();
    }

    /**
     * The identity hash of a handle's current object (the third field of the external form; an
     * update that swaps the object changes it). Assumes: as {@link #handleId}.
     */
    public static int identityHashCode(FactHandle h) {
        return ((InternalFactHandle) h).getIdentityHashCode();
    }

    /**
     * The fact a handle holds, without a session to ask ({@code KieSession.getObject} needs one,
     * and a query row's handle belongs to none). Assumes: as {@link #handleId}.
     */
    public static Object objectOf(FactHandle h) {
        return ((InternalFactHandle) h).getObject();
    }

    /** The name of the entry point a handle's fact was inserted into. Assumes: as {@link #handleId}. */
    public static String entryPointName(FactHandle h) {
        return ((InternalFactHandle) h).getEntryPointName();
    }

    /**
     * A handle's fields as KIE Server writes a {@code DisconnectedFactHandle} (a query row's
     * handle), with {@code value} as its object. Assumes: as {@link #handleId}, plus the
     * recency, object hash and trait type fields of {@code InternalFactHandle}.
     */
    public static Map<String, Object> disconnectedHandle(FactHandle handle, Object value) {
        InternalFactHandle h = (InternalFactHandle) handle;
        Map<String, Object> out = new LinkedHashMap<String, Object>();
        out.put("id", h.getId());
        out.put("identityHashCode", h.getIdentityHashCode());
        out.put("objectHashCode", h.getObjectHashCode());
        out.put("recency", h.getRecency());
        out.put("object", value);
        out.put("traitType", String.valueOf(h.getTraitType()));
        out.put("external", h.toExternalForm());
        return out;
    }

    // ------------------------------------------------------------------ agenda

    /**
     * The agenda group that has the focus ({@code MAIN} when none was set); the public
     * {@code Agenda} can set a focus but not tell it. Assumes: {@code KieSession.getAgenda()}
     * returns the session's {@code InternalAgenda} itself.
     */
    public static String focusName(KieSession session) {
        return ((InternalAgenda) session.getAgenda()).getFocusName();
    }

    /** The private field of Drools' stacked agenda-groups manager that holds the focus stack (see {@link #focusStack}). */
    private static final String FOCUS_STACK_CLASS = "org.drools.core.common.AgendaGroupsManager$StackedAgendaGroupsManager";
    private static final String FOCUS_STACK_FIELD = "focusStack";
    private static volatile java.lang.reflect.Field focusStackField;

    /**
     * The agenda-group focus stack, bottom ({@code MAIN}) to top (the focus), groups that are
     * empty included (a fire pops them): a durable session's snapshot keeps it whole, since the
     * groups below the top fire, in order, once the top one is done; the public {@code Agenda}
     * can push onto it but not tell it. Runs the {@code setFocus()} calls still queued first (the
     * public one only queues its push, which the next fire, or this read, applies), so a focus
     * set and not yet fired is in the stack.
     * Assumes: {@code KieSession.getAgenda()} is the {@code InternalAgenda}, whose
     * {@code flushPropagations()} runs the queued pushes, and whose {@code AgendaGroupsManager} is
     * either a {@code StackedAgendaGroupsManager} keeping the stack in its private {@code Deque}
     * field {@code focusStack} (first = bottom), or a {@code SimpleAgendaGroupsManager} (a rule
     * base without agenda groups: only {@code MAIN}). Another manager fails here, by name.
     */
    public static List<String> focusStack(KieSession session) {
        InternalAgenda agenda = (InternalAgenda) session.getAgenda();
        agenda.flushPropagations();
        List<String> out = new ArrayList<String>();
        for (org.drools.core.common.InternalAgendaGroup group : stackedGroups(agenda)) out.add(group.getName());
        return out;
    }

    /**
     * The focus stack as Drools has applied it so far (bottom to top), the {@code setFocus()} calls
     * still queued <em>not</em> run (unlike {@link #focusStack}), each group with whether it is
     * <em>active</em>: a group turns active when a push or a fire gives it the focus and stays so
     * until another push covers it or a fire pops it empty; while it is, Drools discards new
     * matches of its {@code lock-on-active} rules (those a propagation made after it turned active).
     * A durable session's snapshot keeps this, read before {@link #focusStack}, so that a rebuilt
     * session's {@link Refraction} drops the same re-activations of fired matches. Returns "name"
     * or "name*" (active) per group.
     * Assumes what {@link #focusStack} does, and that its groups are {@code InternalAgendaGroup}s
     * whose {@code isActive()} tells it; a {@code SimpleAgendaGroupsManager} gives its one group.
     */
    public static List<String> appliedFocusStack(KieSession session) {
        List<String> out = new ArrayList<String>();
        for (org.drools.core.common.InternalAgendaGroup group : stackedGroups((InternalAgenda) session.getAgenda())) {
            out.add(group.getName() + (group.isActive() ? "*" : ""));
        }
        return out;
    }

    /**
     * The groups on {@code agenda}'s focus stack as applied so far, bottom to top: the one read of
     * Drools' private stack that {@link #focusStack} and {@link #appliedFocusStack} share (a
     * {@code SimpleAgendaGroupsManager} has only its focus, {@code MAIN}).
     */
    private static List<org.drools.core.common.InternalAgendaGroup> stackedGroups(InternalAgenda agenda) {
        org.drools.core.common.AgendaGroupsManager groups = agenda.getAgendaGroupsManager();
        List<org.drools.core.common.InternalAgendaGroup> out = new ArrayList<org.drools.core.common.InternalAgendaGroup>();
        if (groups instanceof org.drools.core.common.AgendaGroupsManager.SimpleAgendaGroupsManager) {
            out.add(groups.getAgendaGroup(groups.getFocusName()));
            return out;
        }
        Object stack;
        try {
            stack = focusStackField(groups.getClass()).get(groups);
        } catch (ReflectiveOperationException | RuntimeException e) {
            throw new IllegalStateException("Drools' agenda-groups manager " + groups.getClass().getName()
                    + " has no readable focus stack (" + FOCUS_STACK_CLASS + "." + FOCUS_STACK_FIELD + "): " + e, e);
        }
        for (Object group : (Deque<?>) stack) out.add((org.drools.core.common.InternalAgendaGroup) group);
        return out;
    }

    /**
     * The agenda group of a {@code lock-on-active} rule ({@code MAIN} when it names none), or null
     * for a rule without it. Assumes: the public {@code Rule} is a {@code RuleImpl}.
     */
    public static String lockOnActiveGroup(Rule r) {
        if (!(r instanceof RuleImpl) || !((RuleImpl) r).isLockOnActive()) return null;
        String group = ((RuleImpl) r).getAgendaGroup();
        return group == null || group.isEmpty() ? "MAIN" : group;
    }

    private static java.lang.reflect.Field focusStackField(Class<?> manager) throws ReflectiveOperationException {
        java.lang.reflect.Field f = focusStackField;
        if (f != null && f.getDeclaringClass() == manager) return f;
        if (!manager.getName().equals(FOCUS_STACK_CLASS)) throw new ClassNotFoundException("not " + FOCUS_STACK_CLASS);
        f = manager.getDeclaredField(FOCUS_STACK_FIELD);
        f.setAccessible(true);
        focusStackField = f;
        return f;
    }

    /**
     * The agenda groups other than {@code MAIN} that the rules of {@code base} name (the public
     * {@code Rule} does not tell its group; a walk of a whole agenda must focus each in turn).
     * Assumes: the rules a KiePackage lists are {@code RuleImpl}s (another kind names none).
     */
    public static java.util.Set<String> agendaGroups(KieBase base) {
        java.util.Set<String> out = new java.util.TreeSet<String>();
        for (org.kie.api.definition.KiePackage p : base.getKiePackages()) {
            for (Rule r : p.getRules()) {
                if (!(r instanceof RuleImpl)) continue;
                String group = ((RuleImpl) r).getAgendaGroup();
                if (group != null && !group.isEmpty() && !"MAIN".equals(group)) out.add(group);
            }
        }
        return out;
    }

    // ------------------------------------------------------------------ propagations (refraction after a carry)

    /**
     * A mark in a session's propagations: every propagation (insert, update, delete) that starts
     * after this call has a number at least this, every one before it a smaller one. A carried
     * session's {@link Refraction} takes it once its facts are in, to tell the matches nothing
     * has reached since from those something re-created or re-activated (see {@link #lastReachedBy}).
     * Assumes: the {@code KieSession} is a {@code ReteEvaluator} whose
     * {@code getNextPropagationIdCounter()} hands out the increasing numbers the
     * {@code PropagationContext}s of its inserts, updates and deletes carry (it takes one: harmless).
     */
    public static long propagationMark(KieSession session) {
        return ((ReteEvaluator) session).getNextPropagationIdCounter();
    }

    /**
     * The number of the last propagation that reached a match's tuple and could re-activate it:
     * the insert that made it, or a later update of a fact it holds in a property one of its
     * rule's patterns listens to (property reactivity: an update of another property does not reach
     * it, and it keeps its number); or -1 when that last propagation came from its own rule's
     * consequence and the rule is {@code no-loop} (Drools then updates the tuple but does not
     * re-activate it). {@link Long#MAX_VALUE} for a match this does not know how to read (counted
     * as reached: it fires, rather than one being lost).
     * Assumes: the {@code Match} an {@code AgendaFilter} sees is the terminal tuple itself, an
     * {@code AgendaItem} whose {@code getPropagationContext()} is the context of the last
     * propagation staged on it: set by {@code PhreakRuleTerminalNode} at its insert
     * ({@code init}) and at each update ({@code update}, no-loop blocked or not), from the staged
     * tuple's {@code findMostRecentPropagationContext()}; an update whose modification mask the
     * pattern does not intersect is never staged ({@code LeftInputAdapterNode.modifyObject},
     * {@code BetaNode.modifyObject}), so the tuple keeps the context it had.
     */
    public static long lastReachedBy(Match match) {
        if (!(match instanceof AgendaItem)) return Long.MAX_VALUE;
        AgendaItem item = (AgendaItem) match;
        PropagationContext context = item.getPropagationContext();
        if (context == null) return Long.MAX_VALUE;
        RuleImpl rule = item.getRule();
        if (rule != null && rule.isNoLoop() && context.getTerminalNodeOrigin() != null
                && context.getTerminalNodeOrigin().equals(item.getTerminalNode())) return -1;
        return context.getPropagationNumber();
    }

    // ------------------------------------------------------------------ rule and query definitions

    /**
     * The declared parameter types of a query, or null for a query of another kind (JSON numbers
     * must become the declared int/long/...). Assumes: the queries a KiePackage lists are
     * {@code QueryImpl}s whose parameters are {@code Declaration}s with their class.
     */
    public static Class<?>[] queryParameterTypes(Query q) {
        if (!(q instanceof QueryImpl)) return null;
        org.drools.core.rule.Declaration[] ds = ((QueryImpl) q).getParameters();
        Class<?>[] out = new Class<?>[ds.length];
        for (int k = 0; k < ds.length; k++) out[k] = ds[k].getDeclarationClass();
        return out;
    }

    /**
     * Whether a rule has a {@code date-effective} or {@code date-expires} attribute (it compares
     * them with the session clock). Assumes: the rules a KiePackage lists are {@code RuleImpl}s;
     * another kind counts as having none.
     */
    public static boolean hasCalendarAttributes(Rule r) {
        if (!(r instanceof RuleImpl)) return false;
        RuleImpl rule = (RuleImpl) r;
        return rule.getDateEffective() != null || rule.getDateExpires() != null;
    }

    /**
     * Whether a rule can move the agenda's focus: it sits in an agenda group other than MAIN or has
     * auto-focus. Only such rules make the order of propagations matter for which group fires
     * first, so {@code Runner.giveBack} settles an emptied session's deletions only for a rule base
     * with one of them. Assumes: rules are {@code RuleImpl}s (another kind: true, the safe answer)
     * whose {@code getAgendaGroup()} is {@code "MAIN"} (or empty) when none is declared.
     */
    public static boolean movesFocus(Rule r) {
        if (!(r instanceof RuleImpl)) return true;
        RuleImpl rule = (RuleImpl) r;
        String group = rule.getAgendaGroup();
        return rule.getAutoFocus() || (group != null && !group.isEmpty() && !"MAIN".equals(group));
    }

    /**
     * Whether nothing of a rule survives deleting every fact of a session (see
     * {@code Runner.reusable}): a query, or a rule without timer or rule-flow group, whose
     * condition is an AND that opens with a plain pattern on a class (not {@code from}, not the
     * initial fact that not/exists/eval/accumulate start from). Agenda groups and auto-focus are
     * allowed: once the deletions are propagated ({@code Runner.giveBack} fires the emptied
     * session) the focus stack is back to MAIN and no group holds a match.
     * Assumes: rules are {@code RuleImpl}s (another kind: false) whose {@code getLhs()} is the
     * {@code GroupElement} tree of {@code Pattern}s the Rete is built from.
     */
    public static boolean matchesOnlyFromFacts(Rule r) {
        if (!(r instanceof RuleImpl)) return false;
        RuleImpl rule = (RuleImpl) r;
        if (rule.isQuery()) return true;
        if (rule.getTimer() != null) return false;
        if (rule.getRuleFlowGroup() != null && !rule.getRuleFlowGroup().isEmpty()) return false;
        GroupElement lhs = rule.getLhs();
        if (lhs == null || !lhs.isAnd() || lhs.getChildren().isEmpty()) return false;
        Object first = lhs.getChildren().get(0);
        if (!(first instanceof Pattern)) return false;
        Pattern pattern = (Pattern) first;
        if (pattern.getSource() != null) return false;
        // a rule opening with not/exists/eval/accumulate or a query call starts from the
        // session's initial fact: it matches without any fact of the request
        if (!(pattern.getObjectType() instanceof ClassObjectType)) return false;
        Class<?> type = ((ClassObjectType) pattern.getObjectType()).getClassType();
        return type != null && !type.getName().endsWith(".InitialFactImpl");
    }

    // ------------------------------------------------------------------ building with the executable model

    /** The project type for {@code KieBuilder.buildAll}: compile DRL to the executable model. */
    public static Class<ExecutableModelProject> executableModelProject() {
        return ExecutableModelProject.class;
    }

    /** The file names of a built KieModule. Assumes: the module a {@code KieBuilder} built is an {@code InternalKieModule}. */
    public static Collection<String> moduleFileNames(KieModule module) {
        return ((InternalKieModule) module).getFileNames();
    }

    /** One file of a built KieModule (a generated class, the model list). Assumes: as {@link #moduleFileNames}. */
    public static byte[] moduleFile(KieModule module, String fileName) {
        return ((InternalKieModule) module).getBytes(fileName);
    }

    /**
     * The executable-model classes ({@code Rules<uuid>}, one per package) a built KieModule lists.
     * Assumes: the module holds a file ending in {@code /drools-model} that names one model class
     * per line after a {@code Drools-Model-Version} line.
     */
    public static String[] modelClassNames(KieModule module) {
        List<String> out = new ArrayList<String>();
        for (String file : moduleFileNames(module)) {
            if (!file.endsWith("/drools-model")) continue;
            String[] lines = new String(moduleFile(module, file), java.nio.charset.StandardCharsets.UTF_8).split("\n");
            for (String line : lines) {
                line = line.trim();
                if (!line.isEmpty() && !line.startsWith("Drools-Model-Version")) out.add(line);
            }
        }
        return out.toArray(new String[0]);
    }

    /** A KieBase from executable-model objects, without a KieModule or KieContainer. Assumes: {@code KieBaseBuilder.createKieBaseFromModel}. */
    public static KieBase kieBaseFromModels(Collection<Model> models, KieBaseConfiguration conf) {
        return KieBaseBuilder.createKieBaseFromModel(models, conf);
    }

    /**
     * The property indexes of a class as the executable model numbers them: the generated
     * {@code DomainClassesMetadata<hash>} class gives property k of a class index k in
     * {@code ClassUtil.getAccessiblePropertiesIncludingNonGetterValueMethod}. Alpha hashing and
     * property reactivity key on these numbers, so a rule built at run time must use the same.
     * Assumes: the code generator numbers properties with that ClassUtil list.
     */
    public static DomainClassMetadata domainClassMetadata(Class<?> type) {
        return new Metadata(type);
    }

    private static final class Metadata implements DomainClassMetadata {
        private final Class<?> type;
        private final List<String> names;

        Metadata(Class<?> type) {
            this.type = type;
            this.names = ClassUtil.getAccessiblePropertiesIncludingNonGetterValueMethod(type);
        }

        public Class<?> getDomainClass() { return type; }
        public int getPropertiesSize() { return names.size(); }

        public int getPropertyIndex(String name) {
            int i = names.indexOf(name);
            if (i < 0) throw new RuntimeException("Unknown property '" + name + "' for class " + type);
            return i;
        }
    }

    /**
     * The id the executable model gives the constraint {@code _this.getter() op right} on a
     * pattern of {@code type}, or null for an operator it does not write this way. Constraints of
     * equal id are one node to Drools ({@code LambdaConstraint.equals} compares ids), so a rule
     * built at run time shares its nodes with a compiled rule of the same constraint; a different
     * id makes two alpha nodes of one hashed value, and Drools' alpha hashing keeps only one of
     * them: a rule would never fire.
     *
     * Assumes: {@code DRLIdGenerator.getExprId} is {@code "GENERATED_" + md5Hash(type + java)}
     * where {@code java} is the generated expression, written with {@code EvaluationUtil}'s
     * null-safe helpers ({@code areNumbersNullSafeEquals} for numbers, {@code areNullSafeEquals}
     * for the rest, {@code greaterThanNumbers}, ...), negated with {@code !} for {@code !=}.
     *
     * @param numeric whether the field is a number (compared by number, not by equals)
     * @param right the right operand as generated Java text (a literal, or {@code $v.getX()})
     */
    public static String constraintExprId(Class<?> type, String getter, boolean numeric, Index.ConstraintType op, String right) {
        String fn;
        String not = "";
        switch (op) {
            case EQUAL: case NOT_EQUAL:
                fn = numeric ? "areNumbersNullSafeEquals" : "areNullSafeEquals";
                if (op == Index.ConstraintType.NOT_EQUAL) not = "!";
                break;
            case GREATER_THAN: fn = "greaterThanNumbers"; break;
            case GREATER_OR_EQUAL: fn = "greaterOrEqualNumbers"; break;
            case LESS_THAN: fn = "lessThanNumbers"; break;
            case LESS_OR_EQUAL: fn = "lessOrEqualNumbers"; break;
            default: return null;
        }
        String java = not + "org.drools.modelcompiler.util.EvaluationUtil." + fn + "(_this." + getter + "(), " + right + ")";
        return generatedExprId(type, java);
    }

    /**
     * The id the executable model gives the generated constraint {@code java} on {@code type}.
     * Assumes: {@code DRLIdGenerator.getExprId} is {@code "GENERATED_" + md5Hash(type + java)}.
     */
    public static String generatedExprId(Class<?> type, CharSequence java) {
        return "GENERATED_" + StringUtils.md5Hash(String.valueOf(type) + java);
    }

    /**
     * {@code sum(input)} as the executable model generates it for a double. Assumes: the
     * generated code accumulates a {@code sum} with core's {@code SumAccumulateFunction}.
     */
    public static AccumulateFunction sum(Variable<?> input) {
        return DSL.accFunction(SumAccumulateFunction::new, input);
    }

    // ------------------------------------------------------------------ DRL and DSL parsing

    /** Drools' DRL parser at the DRL6 language level (what the compiler parses with). */
    public static DrlParser newDrlParser() {
        return new DrlParser(LanguageLevelOption.DRL6);
    }

    /** A DSL mapping file reader ({@code parseAndLoad}, {@code getErrors}, {@code getMapping}). */
    public static DSLTokenizedMappingFile newDslMappingFile() {
        return new DSLTokenizedMappingFile();
    }

    /** The expander of .dslr texts ({@code addDSLMapping}, {@code expand}, {@code getErrors}). */
    public static DefaultExpander newDslExpander() {
        return new DefaultExpander();
    }

    /**
     * The top-level items of a parsed DRL text, as one JSON string (one JVM crossing per file):
     * {@code {"package": name, "unit": bool, "items": [[kind, name, start, end, line, parent], ...]}}
     * with kind one of rule, query, type, enum, function, window, entrypoint; start/end are the
     * parser's character offsets (refined on the Python side), parent the rule a rule extends.
     * Assumes: {@code DrlParser.parse} returns a {@code PackageDescr} whose descriptors carry
     * start/end character offsets and lines.
     */
    public static String drlItems(Object packageDescr) {
        PackageDescr pd = (PackageDescr) packageDescr;
        StringBuilder b = new StringBuilder(256 + 96 * pd.getRules().size());
        b.append("{\"package\":");
        Json.quote(b, pd.getName() == null ? "" : pd.getName());
        b.append(",\"unit\":").append(pd.getUnit() != null);
        b.append(",\"items\":[");
        boolean[] first = {true};
        for (RuleDescr r : pd.getRules()) {
            item(b, first, r.isQuery() ? "query" : "rule", r.getName(), r, r.getParentName());
        }
        for (TypeDeclarationDescr t : pd.getTypeDeclarations()) item(b, first, "type", t.getTypeName(), t, null);
        for (EnumDeclarationDescr t : pd.getEnumDeclarations()) item(b, first, "enum", t.getTypeName(), t, null);
        for (FunctionDescr f : pd.getFunctions()) item(b, first, "function", f.getName(), f, null);
        for (WindowDeclarationDescr w : pd.getWindowDeclarations()) item(b, first, "window", w.getName(), w, null);
        for (EntryPointDeclarationDescr e : pd.getEntryPointDeclarations()) item(b, first, "entrypoint", e.getEntryPointId(), e, null);
        return b.append("]}").toString();
    }

    private static void item(StringBuilder b, boolean[] first, String kind, String name, BaseDescr d, String parent) {
        if (!first[0]) b.append(',');
        first[0] = false;
        b.append('[');
        Json.quote(b, kind);
        b.append(',');
        Json.quote(b, name == null ? "" : name);
        b.append(',').append(d.getStartCharacter()).append(',').append(d.getEndCharacter());
        b.append(',').append(d.getLine()).append(',');
        if (parent == null) b.append("null"); else Json.quote(b, parent);
        b.append(']');
    }

    // ------------------------------------------------------------------ inspection (the seam test's)

    /**
     * The constraint ids of a rule's patterns on facts, in order (not an accumulate's, nor those on
     * its result: a plain rule gives that one an id of its own, as it shares nothing). For the seam
     * test: a rule built at run time must carry the ids its compiled twin carries. Assumes: the
     * rule's {@code getLhs()} holds {@code Pattern}s whose constraints are the executable model's
     * {@code LambdaConstraint}s.
     */
    public static String[] constraintIds(KieBase kieBase, String packageName, String ruleName) {
        Rule r = kieBase.getRule(packageName, ruleName);
        if (!(r instanceof RuleImpl)) return null;
        List<String> out = new ArrayList<String>();
        Deque<RuleConditionElement> todo = new ArrayDeque<RuleConditionElement>();
        todo.add(((RuleImpl) r).getLhs());
        while (!todo.isEmpty()) {
            RuleConditionElement e = todo.poll();
            if (e instanceof GroupElement) {
                todo.addAll(((GroupElement) e).getChildren());
            } else if (e instanceof Pattern && ((Pattern) e).getSource() == null) {
                for (Constraint c : ((Pattern) e).getConstraints()) {
                    if (c instanceof LambdaConstraint) out.add(((LambdaConstraint) c).getEvaluator().getConstraint().getExprId());
                }
            }
        }
        return out.toArray(new String[0]);
    }

    /**
     * The constraint id of every alpha node of a KieBase's network, once per node, for the seam
     * test: one id twice means two nodes for one constraint (no sharing). Assumes: the KieBase is
     * a {@code RuleBase} whose {@code Rete} lists its {@code ObjectTypeNode}s, whose sinks are the
     * alpha nodes with {@code LambdaConstraint}s.
     */
    public static String[] alphaNodeConstraintIds(KieBase kieBase) {
        List<String> out = new ArrayList<String>();
        Map<Object, Boolean> seen = new IdentityHashMap<Object, Boolean>();
        Deque<ObjectSource> todo = new ArrayDeque<ObjectSource>();
        for (ObjectTypeNode otn : ((RuleBase) kieBase).getRete().getObjectTypeNodes()) todo.add(otn);
        while (!todo.isEmpty()) {
            ObjectSource source = todo.poll();
            for (ObjectSink sink : source.getObjectSinkPropagator().getSinks()) {
                if (!(sink instanceof AlphaNode) || seen.put(sink, Boolean.TRUE) != null) continue;
                AlphaNode alpha = (AlphaNode) sink;
                Object c = alpha.getConstraint();
                out.add(c instanceof LambdaConstraint ? ((LambdaConstraint) c).getEvaluator().getConstraint().getExprId() : String.valueOf(c));
                todo.add(alpha);
            }
        }
        return out.toArray(new String[0]);
    }

    /**
     * The most join, not, exists and accumulate nodes one type's node feeds with no alpha test in
     * between: the memories each of its facts enters on insert ({@code Runner.requestJoinsPay}).
     * Assumes: a {@code RuleBase}'s {@code Rete} lists {@code ObjectTypeNode}s, whose sinks include {@code BetaNode}s.
     */
    public static int untestedRightInputs(KieBase kieBase) {
        int most = 0;
        for (ObjectTypeNode otn : ((RuleBase) kieBase).getRete().getObjectTypeNodes()) {
            int n = 0;
            for (ObjectSink sink : otn.getObjectSinkPropagator().getSinks()) n += sink instanceof org.drools.core.reteoo.BetaNode ? 1 : 0;
            most = Math.max(most, n);
        }
        return most;
    }

    // ---- plain rules: what the executable model's generated code constructs -----------------

    /**
     * A rule of the executable model's DSL with its attributes, set in the map's order (salience
     * first, as the generated code does), its metadata and its items. Assumption: {@code PatternDSL.rule}
     * returns the implementation's {@code RuleBuilder}, whose {@code attribute} returns the builder.
     */
    @SuppressWarnings({"unchecked", "rawtypes"})
    public static org.drools.model.Rule rule(String pkg, String name, Map<org.drools.model.Rule.Attribute, Object> attributes,
                                             Map<String, Object> metadata, org.drools.model.RuleItemBuilder<?>[] items) {
        org.drools.model.impl.RuleBuilder rule = org.drools.model.PatternDSL.rule(pkg, name);
        for (Map.Entry<org.drools.model.Rule.Attribute, Object> a : attributes.entrySet()) rule = rule.attribute(a.getKey(), a.getValue());
        for (Map.Entry<String, Object> m : metadata.entrySet()) rule = rule.metadata(m.getKey(), m.getValue());
        return rule.build(items);
    }

    /**
     * The accumulate function the executable model uses for {@code name} over a value of
     * {@code input} (boxed), or null when its choice is not known here: {@code count} of anything,
     * {@code sum}/{@code min}/{@code max} of doubles ({@code Sum}, {@code NumericMin},
     * {@code NumericMax}; other input types get other functions, left to the compiler).
     */
    static Supplier<?> accumulateFunction(String name, Class<?> input) {
        switch (name) {
            case "count": return org.drools.core.base.accumulators.CountAccumulateFunction::new;
            case "sum": return input == Double.class ? SumAccumulateFunction::new : null;
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

    /** The mask {@link #ruleDate} reads ({@code drools.dateformat}, by default {@code dd-MMM-yyyy}). */
    static String ruleDateFormat() {
        return org.drools.util.DateUtils.getDateFormatMask();
    }

    /** 1 January 2020 written in that mask: the example an error about a bad date shows. */
    static String ruleDateExample() {
        return LocalDate.of(2020, 1, 1).format(DateTimeFormatter.ofPattern(ruleDateFormat(), Locale.ENGLISH));
    }
}
