"""Helpers of the ROS 2 tests and the node benchmark: a short ride (course, plan, ride
log) and the `itt-planner` processes of a pipeline (the loopback-only environment is
the `ros_env` fixture of conftest.py, or `itt_msgs_py.dds_env.localhost_env`)."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from itt_planner_ros.signals import STACKS_SIGNAL

#: POSIX stamp of the synthetic ride's start (2026-11-22 08:00 UTC).
RIDE_T0_S = 1795334400.0
#: The rider of the test ride (its full-course plan on the hairpin course converges).
RIDER = "typical"
#: The model of the test ride's plan: the ROS tests are about the node's plumbing, and the
#: 1D plan (0.6 s; the horizon is 3D either way) spares them the 3D solve (25 s CPU).
TEST_PLAN_MODEL = "1d"


@dataclass(frozen=True)
class Ride:
    """A short synthetic ride: course file, full-course plan, and the sensors' ride log."""

    course: Path
    plan: Path
    log: Path
    duration_s: float


def make_ride(folder: Path, *, input_hz: float = 4.0, gps_hz: float = 1.0,
              duration_s: float | None = None, seed: int = 1, model: str = "3d") -> Ride:
    """Ride the hairpin test course (~2.7 km, ~3 min) along its optimal plan.

    The truth is the plan's trajectory (of `model`); the sensors
    (`simulate.sensor_samples`: GPS bias + noise, wheel speed, power) sample it at the
    given rates. The course and plan are solved once per folder and model.
    """
    from itt_planner.logs.ridelog_writer import RideLogWriter, RideMetadata
    from itt_planner.sim import SensorSettings, sensor_samples

    folder.mkdir(parents=True, exist_ok=True)
    course, plan, course_path, plan_path = _course_and_plan(folder.parent, model)
    end = plan.finish_time_s if duration_s is None else min(duration_s, plan.finish_time_s)
    t = np.arange(0.0, end, 1.0 / max(input_hz, gps_hz) / 2)
    s = np.interp(t, plan.t_s, plan.s_m)
    samples = sensor_samples(
        course, t, s, np.interp(s, plan.s_m, plan.n_m), np.interp(s, plan.s_m, plan.v_mps),
        np.interp(s, plan.s_m, plan.power_w), np.random.default_rng(seed),
        SensorSettings(gps_period_s=1.0 / gps_hz, speed_period_s=1.0 / input_hz,
                       power_period_s=1.0 / input_hz), t0_s=RIDE_T0_S)
    ride = Ride(course=course_path, plan=plan_path, log=folder / "ride.mcap",
                duration_s=float(end))
    with RideLogWriter(ride.log, metadata=RideMetadata(source="tests/ros_support.py",
                                                       rider=RIDER)) as writer:
        for sample in samples:
            writer.write_sample(sample)
    return ride


_SOLVED: dict[tuple[Path, str], tuple[Any, Any, Path, Path]] = {}


def _course_and_plan(folder: Path, model: str) -> tuple[Any, Any, Path, Path]:
    """The hairpin course and its `RIDER` plan, solved and saved once per folder and model."""
    if (folder, model) not in _SOLVED:
        from itt_planner.model.rider import PRESETS
        from itt_planner.ocp.course_problem import solve_plan
        from itt_planner.sim import hairpin_course

        course = hairpin_course()
        plan = solve_plan(course, PRESETS[RIDER], model=model)
        if not plan.converged:
            raise RuntimeError(f"the test ride's {model} plan is {plan.status}")
        _SOLVED[folder, model] = (course, plan, course.save(folder / "hairpin.course.npz"),
                                  plan.save(folder / f"hairpin_{model}.plan.npz"))
    return _SOLVED[folder, model]


def cli(*args: str) -> list[str]:
    """Command line of `itt-planner ARGS` with this interpreter."""
    return [sys.executable, "-c", "from itt_planner.cli import main; main()", *args]


class Proc:
    """A background `itt-planner` process with its stderr in a file."""

    def __init__(self, args: list[str], env: dict[str, str], log: Path) -> None:
        self.log = log
        self._err = log.open("wb")
        self.popen = subprocess.Popen(args, env=env, stdout=subprocess.PIPE, stderr=self._err)

    def text(self) -> str:
        """What the process wrote on stderr so far."""
        return self.log.read_text(errors="replace")

    def wait_for(self, needle: str, timeout_s: float) -> None:
        """Wait until stderr contains `needle`; fail with the log when it does not."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if needle in self.text():
                return
            if self.popen.poll() is not None:
                break
            time.sleep(0.1)
        raise AssertionError(f"{needle!r} not seen (rc={self.popen.poll()}):\n{self.text()}")

    def stop(self, sig: int = signal.SIGTERM, timeout_s: float = 30.0) -> str:
        """Signal the process, wait for it, return its stdout."""
        if self.popen.poll() is None:
            self.popen.send_signal(sig)
        return self.wait(timeout_s)

    def wait(self, timeout_s: float) -> str:
        """Wait for the process to end by itself; its stdout."""
        try:
            out, _ = self.popen.communicate(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            self.dump_stacks()
            self.popen.kill()
            raise AssertionError(f"still running after {timeout_s} s:\n{self.text()}") from None
        finally:
            self._err.close()
        return out.decode()

    def dump_stacks(self) -> None:
        """Have the process write every thread's Python stack to its log (the CLI's
        `faulthandler` on `STACKS_SIGNAL`), so a hung process says where it hangs."""
        if self.popen.poll() is None:
            self.popen.send_signal(STACKS_SIGNAL)
            time.sleep(1.0)

    def rss_mb(self) -> float:
        """Resident memory of the process (MB, from /proc)."""
        fields = Path(f"/proc/{self.popen.pid}/status").read_text().split("\n")
        line = next(f for f in fields if f.startswith("VmRSS:"))
        return int(line.split()[1]) / 1024



def stop_all(*procs: Proc) -> list[str]:
    """`Proc.stop` each process in turn, every one even when an earlier one fails (a
    recorder left running records the next tests on its domain); their stdouts. The
    first failure is raised once all are stopped."""
    outs: list[str] = []
    failure: AssertionError | None = None
    for proc in procs:
        try:
            outs.append(proc.stop())
        except AssertionError as err:
            failure = failure or err
            outs.append("")
    if failure is not None:
        raise failure
    return outs


_RIDES: dict[tuple[float, float, float | None], Ride] = {}


def cached_ride(folder: Path, *, input_hz: float = 4.0, gps_hz: float = 1.0,
                duration_s: float | None = None) -> Ride:
    """`make_ride` along the `TEST_PLAN_MODEL` plan, once per test process and settings."""
    key = (input_hz, gps_hz, duration_s)
    if key not in _RIDES:
        _RIDES[key] = make_ride(folder / f"ride_{input_hz:g}_{gps_hz:g}_{duration_s}",
                                input_hz=input_hz, gps_hz=gps_hz, duration_s=duration_s,
                                model=TEST_PLAN_MODEL)
    return _RIDES[key]
