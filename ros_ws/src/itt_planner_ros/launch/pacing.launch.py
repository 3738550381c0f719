# Copyright 2026 itt-planner team
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""Launch the pacing node: `ros2 launch itt_planner_ros pacing.launch.py [course:=...]`.

Replaying a ride log into it: `ros2 bag play ride.mcap --clock` with `use_sim_time:=true`.
"""

from pathlib import Path

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

ARGUMENTS = {
    'namespace': ('itt', 'ROS namespace of the pacing topics'),
    'course': ('verona-like', 'demo course name, GPS track or .course.npz'),
    'rider': ('paper', 'rider preset or YAML file'),
    'use_sim_time': ('false', 'follow /clock (true when replaying with --clock)'),
    'rerun_sink': ('', 'Rerun destination: file:ride.rrd, spawn, connect[:URL], serve'),
    'output_log': ('', 'MCAP ride log of inputs and outputs'),
}


def generate_launch_description():
    """Start the node with config/params.yaml, overridden by the launch arguments."""
    params_file = str(Path(get_package_share_directory('itt_planner_ros'))
                      / 'config' / 'params.yaml')
    declared = [DeclareLaunchArgument(name, default_value=default, description=text)
                for name, (default, text) in ARGUMENTS.items()]
    overrides = {name: LaunchConfiguration(name)
                 for name in ('course', 'rider', 'rerun_sink', 'output_log')}
    node = Node(
        package='itt_planner_ros',
        executable='pacing_node',
        name='itt_pacing',
        namespace=LaunchConfiguration('namespace'),
        parameters=[params_file, overrides,
                    {'use_sim_time': LaunchConfiguration('use_sim_time')}],
        output='screen',
        emulate_tty=True,
    )
    return LaunchDescription([*declared, node])
