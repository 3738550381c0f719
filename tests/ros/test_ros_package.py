"""The ROS 2 packages as ROS tooling sees them: package.xml against format 3 (catkin_pkg,
the parser of ROS tooling), the node's ROS imports declared, colcon building and installing
the node package where `ros2 run` and `ros2 launch` look, the installed console script
running on real rclpy with `--ros-args`, the parameter and launch files agreeing with the
node, the whole workspace (itt_msgs too) built by colcon against the ROS 2 wheels (slow),
and the Dockerfile."""

from __future__ import annotations

import ast
import importlib.util
import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from dataclasses import fields
from pathlib import Path
from types import ModuleType

import pytest
import yaml
from catkin_pkg.package import parse_package
from support.ros_support import Proc, Ride, cached_ride

ROOT = Path(__file__).resolve().parents[2]
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


def _top_level_imports(path: Path) -> set[str]:
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            names |= {alias.name.split(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names


def _is_ros_package(name: str) -> bool:
    """ROS packages the node could import (the rest are pip dependencies of the core)."""
    return (name in {"rclpy", "rosidl_runtime_py", "launch", "launch_ros", "rosbag2_py"}
            or name.endswith(("_msgs", "_interfaces")))


def test_node_package_declares_the_ros_packages_it_imports() -> None:
    package = parse_package(PKG)
    assert package.get_build_type() == "ament_python"
    exec_deps = {d.name for d in package.exec_depends}
    imports = set().union(*map(_top_level_imports, (PKG / "itt_planner_ros").glob("*.py")))
    ros_imports = {name for name in imports if _is_ros_package(name)}
    assert {"rclpy", "itt_msgs_py"} <= imports
    assert ros_imports <= exec_deps, f"undeclared: {sorted(ros_imports - exec_deps)}"
    # rosidl_runtime_py is not on PyPI: the node uses what rclpy and the generated
    # packages give (it may stay declared for the apt-installed Docker image).
    assert "rosidl_runtime_py" not in imports
    assert "itt_msgs" in exec_deps and (PKG / "resource" / "itt_planner_ros").is_file()


def _colcon(build: Path, *args: str, timeout_s: float,
            env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    colcon = Path(sys.executable).with_name("colcon")
    proc = subprocess.run(
        [str(colcon), "--log-base", str(build / "log"), "build",
         "--base-paths", str(ROOT / "ros_ws" / "src"), "--build-base", str(build / "build"),
         "--install-base", str(build / "install"), *args],
        cwd=build, env=env, check=False, capture_output=True, text=True, timeout=timeout_s)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The node package built and installed by colcon itself (colcon-ros's ament_python
    build, ~5 s). `itt_msgs` is left out of this crawl: set-up already built it into the
    venv, and its colcon build is the slow test below."""
    build = tmp_path_factory.mktemp("colcon")
    proc = _colcon(build, "--packages-ignore", "itt_msgs", timeout_s=300)
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


def _node_names(timeout_s: float, want: tuple[str, str]) -> list[tuple[str, str]]:
    """Node names and namespaces an in-process rclpy participant discovers (this test's
    domain, loopback only), polled until `want` shows up or the time is over."""
    import rclpy
    from rclpy.context import Context

    context = Context()
    rclpy.init(context=context)
    try:
        probe = rclpy.create_node("itt_test_probe", context=context)
        deadline = time.monotonic() + timeout_s
        names = probe.get_node_names_and_namespaces()
        while want not in names and time.monotonic() < deadline:
            time.sleep(0.2)
            names = probe.get_node_names_and_namespaces()
        probe.destroy_node()
        return names
    finally:
        rclpy.shutdown(context=context)


def test_installed_node_runs_on_real_rclpy_with_ros_args(
        installed: Path, ros_env: dict[str, str], tmp_path: Path,
        tmp_path_factory: pytest.TempPathFactory) -> None:
    """`ros2 run itt_planner_ros pacing_node --ros-args ...`, minus `ros2 run`: the script
    colcon installed, its package from the install tree, the messages from the venv."""
    ride: Ride = cached_ride(tmp_path_factory.getbasetemp())
    site = next(installed.glob("lib/python3*/site-packages"))
    env = dict(ros_env, PYTHONPATH=os.pathsep.join(
        p for p in (str(site), ros_env.get("PYTHONPATH", "")) if p))
    params = installed / "share" / "itt_planner_ros" / "config" / "params.yaml"
    node = Proc([sys.executable, str(installed / "lib" / "itt_planner_ros" / "pacing_node"),
                 "--ros-args", "--params-file", str(params), "-r", "__ns:=/team",
                 "-p", f"course:={ride.course}", "-p", f"plan:={ride.plan}",
                 "-p", f"state_file:={tmp_path / 'state.json'}"],
                env, tmp_path / "node.log")
    try:
        node.wait_for("ready on /team", 120)
        assert ("itt_pacing", "/team") in _node_names(30.0, ("itt_pacing", "/team"))
    finally:
        node.stop(signal.SIGINT)
    assert node.popen.returncode == 0, node.text()
    assert "Traceback" not in node.text()
    assert (tmp_path / "state.json").is_file()  # saved at exit
    where = subprocess.run(
        [sys.executable, "-c", "import itt_planner_ros.pacing_node as m; print(m.__file__)"],
        env=env, capture_output=True, text=True, check=True).stdout
    assert where.startswith(str(site))


def _node_parameters() -> dict[str, object]:
    """Every parameter the node declares with its default (session's and node's own)."""
    from itt_planner_ros.pacing_node import NODE_PARAMS

    from itt_planner.session.config import SessionConfig

    session = {f.name: f.default for f in fields(SessionConfig) if f.name != "namespace"}
    return {**session, **NODE_PARAMS}


@pytest.mark.usefixtures("requires_ros")
def test_params_yaml_matches_the_node_parameters() -> None:
    doc = yaml.safe_load((PKG / "config" / "params.yaml").read_text())
    params = doc["/**"]["ros__parameters"]
    defaults = _node_parameters()
    assert set(params) == set(defaults)
    for name, value in params.items():
        # rclpy types parameters strictly: a float default needs a float in the file.
        assert type(value) is type(defaults[name]), name


@pytest.mark.usefixtures("requires_ros")
def test_launch_file_is_valid_python_and_agrees_with_the_package() -> None:
    from itt_planner_ros.pacing_node import NODE_NAME

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
                     and "course" in [getattr(e, "value", None) for e in n.elts])
    assert {getattr(e, "value", None) for e in overrides.elts} <= set(_node_parameters())


def _build_interfaces_module() -> ModuleType:
    """ros_ws/build_interfaces.py (a script, not a package), for its CMake arguments."""
    path = ROOT / "ros_ws" / "build_interfaces.py"
    spec = importlib.util.spec_from_file_location("build_interfaces", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.slow
@pytest.mark.usefixtures("requires_ros")
def test_colcon_builds_the_whole_workspace_against_the_ros_wheels(tmp_path: Path) -> None:
    """What the Docker image does with apt's ROS, here with the PyPI wheels (1-2 min): colcon
    builds itt_msgs (rosidl, ament_cmake) and itt_planner_ros, and the generated messages
    import from the install tree alone, as after `source install/setup.bash`."""
    cmake_args = _build_interfaces_module().cmake_args()
    # colcon hands ament_cmake the ROS packages it finds through the ament index: the venv.
    proc = _colcon(tmp_path, "--cmake-args", *cmake_args, timeout_s=900,
                   env=dict(os.environ, AMENT_PREFIX_PATH=sys.prefix))
    assert "Finished <<< itt_msgs" in proc.stdout
    assert "Finished <<< itt_planner_ros" in proc.stdout
    prefix = tmp_path / "install" / "itt_msgs"
    assert (prefix / "share/ament_index/resource_index/packages/itt_msgs").is_file()
    assert (prefix / "share/itt_msgs/msg/Advice.msg").read_text() == (
        MSGS / "msg" / "Advice.msg").read_text()
    site = next(prefix.glob("lib/python3*/site-packages"))
    # The wheels' bootstrapper re-executes Python with its own LD_LIBRARY_PATH unless told
    # it already ran; set the library path as setup.bash would (the install tree first).
    env = dict(os.environ, PYTHONPATH=str(site), _ROS_WHEELS_BOOTSTRAP_COMPLETE="1",
               AMENT_PREFIX_PATH=os.pathsep.join([str(prefix), sys.prefix]),
               LD_LIBRARY_PATH=os.pathsep.join(
                   [str(prefix / "lib"), os.environ.get("LD_LIBRARY_PATH", "")]))
    code = textwrap.dedent("""
        import re
        import itt_msgs.msg as m
        from rclpy.serialization import deserialize_message, serialize_message
        msg = m.Advice(target_power_w=305.5, solver_status="on_plan")
        back = deserialize_message(serialize_message(msg), m.Advice)
        assert back == msg, back
        maps = open("/proc/self/maps").read()
        print(m.__file__)
        print(sorted(set(re.findall(r"\\S*libitt_msgs__rosidl_generator_py.so", maps))))
    """)
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, check=False)
    assert out.returncode == 0, out.stderr
    module_file, libraries = out.stdout.splitlines()
    assert module_file.startswith(str(site))
    assert libraries == repr([str(prefix / "lib" / "libitt_msgs__rosidl_generator_py.so")])


def test_dockerfile_builds_on_ros_jazzy_with_colcon_and_fast_dds() -> None:
    """Not built here (no Docker engine): its structure and every path it copies."""
    text = (ROOT / "Dockerfile").read_text()
    assert "\nFROM ros:jazzy\n" in text
    assert "colcon build" in text
    assert "cyclone" not in text.lower()
    code = "\n".join(line for line in text.splitlines() if not line.startswith("#"))
    assert re.search(r"RMW_IMPLEMENTATION=rmw_fastrtps_cpp\b", code)
    assert "ROS_AUTOMATIC_DISCOVERY_RANGE" not in code  # LOCALHOST would widen the sockets
    profile = re.search(r"^ENV FASTRTPS_DEFAULT_PROFILES_FILE=(\S+)$", code, re.MULTILINE)
    workdir = re.search(r"^WORKDIR (\S+)$", code, re.MULTILINE)  # the first: the sources
    assert profile and workdir
    assert profile[1] == f"{workdir[1]}/itt_msgs_py/fastdds_localhost.xml"
    for line in text.splitlines():
        if line.startswith("COPY "):
            for src in line.split()[1:-1]:
                assert (ROOT / src).exists(), src
