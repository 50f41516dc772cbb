package org.printeps.gateway;

import java.util.ArrayList;
import java.util.LinkedHashMap;
import java.util.List;
import java.util.Map;

/**
 * The then-part's way to talk to robots: the global {@code actions} of every rule set.
 *
 * Rules never call robots directly: each call here records a structured action
 * ({@code {"module": "say", "params": {...}}}) that the gateway returns to the caller and
 * dispatches to the robot's ROS service. The rule that requested it is recorded too.
 */
public class Actions {
    private final List<Map<String, Object>> recorded = new ArrayList<Map<String, Object>>();
    private String currentRule;

    /** Make {@code robot} say {@code text}. */
    public void say(String robot, String text) {
        record("say", params("robot", robot, "text", text));
    }

    /** Move {@code robot} to a named {@code location} (e.g. "entrance", "table1"). */
    public void move(String robot, String location) {
        record("move", params("robot", robot, "location", location));
    }

    /** Make {@code robot} perform the gesture {@code name} (e.g. "bow", "wave"). */
    public void gesture(String robot, String name) {
        record("gesture", params("robot", robot, "name", name));
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
        call(module, params(keyValues));
    }

    private static Map<String, Object> params(Object... kv) {
        Map<String, Object> m = new LinkedHashMap<String, Object>();
        for (int k = 0; k + 1 < kv.length; k += 2) m.put(String.valueOf(kv[k]), kv[k + 1]);
        return m;
    }

    private void record(String module, Map<String, Object> params) {
        if (module == null || module.isEmpty()) throw new IllegalArgumentException("an action needs a module name");
        Map<String, Object> a = new LinkedHashMap<String, Object>();
        a.put("module", module);
        a.put("params", params);
        if (currentRule != null) a.put("rule", currentRule);
        recorded.add(a);
    }

    void setCurrentRule(String rule) { this.currentRule = rule; }

    /** The actions recorded since the last drain, in order. */
    List<Map<String, Object>> drain() {
        List<Map<String, Object>> out = new ArrayList<Map<String, Object>>(recorded);
        recorded.clear();
        return out;
    }
}
