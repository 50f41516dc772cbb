"""ROS 2 side of the gateway: the gateway node, the simulators and their plain-Python core.

Plain-Python modules (no rclpy import): readings, detector, pipeline, dispatcher, scenario.
ROS adapters (import rclpy + printeps_interfaces): runtime, convert, node, replay (what simulated sensors share), sim_sensor, sim_tables, sim_robot.
See docs/ros.md.
"""
