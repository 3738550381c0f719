"""ROS 2 without a ROS install: an rclpy-compatible layer over Cyclone DDS.

`itt_planner.dds.rclpy` offers the part of rclpy's API the pacing node uses (nodes,
publishers and subscriptions with QoS, timers, callback groups, executors, parameters,
`use_sim_time`, loggers), speaking the ROS 2 wire conventions of `rmw_cyclonedds_cpp`
(`wire`), so the same node module runs on real rclpy or here, and talks to ROS 2
machines either way. `endpoints` carries raw CDR payloads; `context` holds the DDS
participant and the process-wide start/stop state.
"""

from __future__ import annotations
