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

"""ament_python build of the itt_planner_ros package (as `ros2 pkg create` lays it out).

The node imports the core (`itt_planner`, `itt_msgs_py`), which the Docker image
installs with pip from the repository root.
"""

from glob import glob

from setuptools import find_packages, setup

package_name = 'itt_planner_ros'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='itt-planner team',
    maintainer_email='itt-planner@example.org',
    description='Pacing node of itt-planner',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'pacing_node = itt_planner_ros.pacing_node:main',
        ],
    },
)
