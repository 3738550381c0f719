"""The ROS 2 packages are valid as far as can be checked without ROS 2: package.xml
against format 3 (catkin_pkg, the parser of ROS tooling), what colcon builds and installs
where `ros2 run` and `ros2 launch` look, the node's console script running on the DDS layer, the launch file and
the parameter file agreeing with the node."""

from __future__ import annotations

import ast
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
import yaml
from catkin_pkg.package import parse_package
from dds_support import Proc, Ride, cached_ride, dds_env

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "ros_ws" / "src" / "itt_planner_ros"
MSGS = ROOT / "ros_ws" / "src" / "itt_msgs"


@pytest.mark.parametrize("folder", [PKG, MSGS], ids=["itt_planner_ros", "itt_msgs"])
def test_package_xml_is_valid_format_3(folder: Path) -> None:
    package = parse_package(folder)  # raises InvalidPackage on schema violations
    warnings: list[str] = []
    package.validate(warnings=warnings)
    assert warnings == []
    assert package.package_format == 3
    assert package.name == folder.name
    assert package.licenses == ["Apache-2.0"]


def test_node_package_declares_what_the_node_uses() -> None:
    package = parse_package(PKG)
    assert package.get_build_type() == "ament_python"
    exec_deps = {d.name for d in package.exec_depends}
    assert {"rclpy", "rosidl_runtime_py", "itt_msgs", "sensor_msgs", "geometry_msgs",
            "nav_msgs", "diagnostic_msgs", "rosgraph_msgs", "launch_ros"} <= exec_deps
    assert (PKG / "resource" / "itt_planner_ros").is_file()


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The node package built and installed by colcon itself (colcon-ros's ament_python
    build). `itt_msgs` is an ament_cmake package that needs a ROS 2 install to build, so it
    is left out of the crawl and treated as an external dependency."""
    build = tmp_path_factory.mktemp("colcon")
    colcon = Path(sys.executable).with_name("colcon")
    proc = subprocess.run(
        [str(colcon), "--log-base", str(build / "log"), "build",
         "--base-paths", str(ROOT / "ros_ws" / "src"), "--packages-ignore", "itt_msgs",
         "--build-base", str(build / "build"), "--install-base", str(build / "install")],
        cwd=build, check=False, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "Finished <<< itt_planner_ros" in proc.stdout
    return build / "install" / "itt_planner_ros"


def test_colcon_installs_launch_config_marker_and_script(installed: Path) -> None:
    share = installed / "share" / "itt_planner_ros"
    assert (installed / "share/ament_index/resource_index/packages/itt_planner_ros").is_file()
    assert (share / "package.xml").read_text() == (PKG / "package.xml").read_text()
    assert (share / "launch" / "pacing.launch.py").is_file()
    assert (share / "config" / "params.yaml").is_file()
    # setup.cfg puts the console script where `ros2 run` looks: lib/<package>/.
    assert (installed / "lib" / "itt_planner_ros" / "pacing_node").is_file()
    site = next(installed.glob("lib/python3*/site-packages"))
    assert (site / "itt_planner_ros" / "pacing_node.py").is_file()


def test_installed_node_runs_on_the_dds_layer_with_ros_args(
        installed: Path, tmp_path: Path, tmp_path_factory: pytest.TempPathFactory) -> None:
    """`ros2 run itt_planner_ros pacing_node --ros-args ...`, minus `ros2 run`."""
    ride: Ride = cached_ride(tmp_path_factory.getbasetemp())
    site = next(installed.glob("lib/python3*/site-packages"))
    env = dds_env()
    env["PYTHONPATH"] = str(site)
    del env["ITT_RUNTIME"]  # automatic: rclpy is not installed here, so the DDS layer
    params = installed / "share" / "itt_planner_ros" / "config" / "params.yaml"
    node = Proc([sys.executable, str(installed / "lib" / "itt_planner_ros" / "pacing_node"),
                 "--ros-args", "--params-file", str(params), "-r", "__ns:=/team",
                 "-p", f"course:={ride.course}", "-p", f"plan:={ride.plan}",
                 "-p", f"state_file:={tmp_path / 'state.json'}"],
                env, tmp_path / "node.log")
    try:
        node.wait_for("ready on /team (dds)", 120)
    finally:
        node.stop()
    assert node.popen.returncode == 0, node.text()
    assert "itt_planner_ros/pacing_node.py" not in node.text()  # no traceback
    assert (tmp_path / "state.json").is_file()  # saved at exit
    spec = subprocess.run([sys.executable, "-c", textwrap.dedent("""
        import itt_planner_ros.pacing_node as m; print(m.__file__, m.RUNTIME)""")],
        env=env, capture_output=True, text=True, check=True).stdout
    assert spec.startswith(str(site)) and spec.split()[-1] == "dds"


def test_params_yaml_matches_the_node_parameters() -> None:
    from itt_planner_ros.pacing_node import NodeParams

    doc = yaml.safe_load((PKG / "config" / "params.yaml").read_text())
    params = doc["/**"]["ros__parameters"]
    defaults = NodeParams()
    assert set(params) == set(NodeParams.__dataclass_fields__)
    for name, value in params.items():
        # rclpy types parameters strictly: a float default needs a float in the file.
        assert type(value) is type(getattr(defaults, name)), name


def test_launch_file_is_valid_python_and_agrees_with_the_package() -> None:
    from itt_planner_ros.pacing_node import NODE_NAME, NodeParams

    path = PKG / "launch" / "pacing.launch.py"
    tree = ast.parse(path.read_text(), filename=str(path))
    compile(tree, str(path), "exec")
    functions = {n.name for n in tree.body if isinstance(n, ast.FunctionDef)}
    assert "generate_launch_description" in functions
    strings = {n.value for n in ast.walk(tree) if isinstance(n, ast.Constant)
               and isinstance(n.value, str)}
    assert {"itt_planner_ros", "pacing_node", NODE_NAME, "params.yaml"} <= strings
    # Launch arguments passed as node parameters must be parameters of the node.
    overrides = next(n for n in ast.walk(tree) if isinstance(n, ast.Tuple)
                     and all(isinstance(e, ast.Constant) for e in n.elts)
                     and "course" in [e.value for e in n.elts])
    assert {e.value for e in overrides.elts} <= set(NodeParams.__dataclass_fields__)


def test_dockerfile_builds_on_ros_jazzy_with_colcon() -> None:
    text = (ROOT / "Dockerfile").read_text()
    assert "\nFROM ros:jazzy\n" in text
    assert "colcon build" in text and "rmw_cyclonedds_cpp" in text
    for line in text.splitlines():
        if line.startswith("COPY "):
            for src in line.split()[1:-1]:
                assert (ROOT / src).exists(), src
