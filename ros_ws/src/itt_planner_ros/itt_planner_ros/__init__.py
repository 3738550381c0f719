"""ROS 2 package of itt-planner: the pacing node (`pacing_node`), on rclpy or the DDS layer."""
