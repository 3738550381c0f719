"""ament_python build of the itt_planner_ros package (as `ros2 pkg create` lays it out).

The node imports the core (`itt_planner`, `itt_msgs_py`), which the Docker image
installs with pip from the repository root.
"""

from glob import glob

from setuptools import find_packages, setup

package_name = "itt_planner_ros"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/launch", glob("launch/*.launch.py")),
        ("share/" + package_name + "/config", glob("config/*.yaml")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="itt-planner team",
    maintainer_email="itt-planner@example.org",
    description="Pacing node of itt-planner",
    license="Apache-2.0",
    tests_require=["pytest"],
    entry_points={
        "console_scripts": [
            "pacing_node = itt_planner_ros.pacing_node:main",
        ],
    },
)
