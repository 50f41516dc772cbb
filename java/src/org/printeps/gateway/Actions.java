package org.printeps.gateway;

import java.util.LinkedHashMap;
import java.util.Map;

/**
 * The then-part's way to talk to robots: the global {@code actions} of every rule set.
 *
 * Rules never call robots directly: each call here records a structured action
 * ({@code {"module": "say", "params": {...}}}) that the gateway returns to the caller and
 * dispatches to the robot's ROS service. The rule that requested it is recorded too.
 */
public class Actions {
    /** The recorded actions as JSON objects separated by commas: written at once, so a then-part's
     *  parameters are captured as they were when it ran, and no maps are built per action. */
    private final StringBuilder json = new StringBuilder(256);
    private int count;
    private String currentRule;
    private TypeRegistry types;  // writes declared facts passed as parameters

    /** Make {@code robot} say {@code text}. */
    public void say(String robot, String text) {
        record("say", "robot", robot, "text", text);
    }

    /** Move {@code robot} to a named {@code location} (e.g. "entrance", "table1"). */
    public void move(String robot, String location) {
        record("move", "robot", robot, "location", location);
    }

    /** Make {@code robot} perform the gesture {@code name} (e.g. "bow", "wave"). */
    public void gesture(String robot, String name) {
        record("gesture", "robot", robot, "name", name);
    }

    /** Call any module (a ROS service or workflow module) with parameters. */
    public void call(String module, Map<?, ?> params) {
        Map<String, Object> copy = new LinkedHashMap<String, Object>();
        if (params != null) {
            for (Map.Entry<?, ?> e : params.entrySet()) copy.put(String.valueOf(e.getKey()), e.getValue());
        }
        record(module, copy);
    }

    /** Same as {@link #call(String, Map)} with alternating key/value arguments. */
    public void call(String module, Object... keyValues) {
        Map<String, Object> m = new LinkedHashMap<String, Object>();
        for (int k = 0; k + 1 < keyValues.length; k += 2) m.put(String.valueOf(keyValues[k]), keyValues[k + 1]);
        record(module, m);
    }

    private void record(String module, String key1, Object value1, String key2, Object value2) {
        int mark = begin(module);
        try {
            json.append('{');
            Json.quote(json, key1);
            json.append(':');
            Json.write(json, value1, types);
            json.append(',');
            Json.quote(json, key2);
            json.append(':');
            Json.write(json, value2, types);
            json.append('}');
        } catch (RuntimeException | StackOverflowError e) {
            json.setLength(mark);
            throw e;
        }
        end();
    }

    private void record(String module, Map<String, Object> params) {
        int mark = begin(module);
        try {
            Json.write(json, params, types);
        } catch (RuntimeException | StackOverflowError e) {  // e.g. a parameter that contains itself
            json.setLength(mark);
            throw e;
        }
        end();
    }

    /** Opens {"module":...,"params": and returns where this action starts (to undo on failure). */
    private int begin(String module) {
        if (module == null || module.isEmpty()) throw new IllegalArgumentException("an action needs a module name");
        int mark = json.length();
        if (count > 0) json.append(',');
        json.append("{\"module\":");
        Json.quote(json, module);
        json.append(",\"params\":");
        return mark;
    }

    private void end() {
        if (currentRule != null) {
            json.append(",\"rule\":");
            Json.quote(json, currentRule);
        }
        json.append('}');
        count++;
    }

    void setCurrentRule(String rule) { this.currentRule = rule; }

    void setTypes(TypeRegistry types) { this.types = types; }

    /** Appends the actions recorded since the last drain as a JSON list, in order, and forgets them. */
    void drainInto(StringBuilder b) {
        b.append('[').append(json).append(']');
        clear();
    }

    /** Forgets the recorded actions. */
    void clear() {
        json.setLength(0);
        count = 0;
    }
}
