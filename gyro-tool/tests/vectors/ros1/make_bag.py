#!/usr/bin/env python3
"""A ROS 1 bag of `sensor_msgs/Imu`, written by the `rosbags` library (not by
this project), the fixture of `gyro_tool::ros1` (test
`an_imu_topic_reads_as_rosbags_wrote_it`).

    python3 -m venv /tmp/v && /tmp/v/bin/pip install rosbags==0.11.9
    /tmp/v/bin/python gyro-tool/tests/vectors/ros1/make_bag.py gyro-tool/tests/vectors/ros1

Writes `imu.bag`: topic `/imu`, 300 messages at 100 Hz (angular velocity
x, y, z = 0.002·k, −0.3, 0.05·cos(k/5) rad/s; header stamps
1 600 000 000 s + 10 ms·k, frame ids of varying length, message 100
dropped), and topic `/chatter` (`std_msgs/String`, skipped); and
`expected.csv`: the stamps (s) and rates (rad/s) as written.
"""
import math
import sys
from pathlib import Path

import numpy as np
from rosbags.rosbag1 import Writer
from rosbags.typesys import Stores, get_typestore

out = Path(sys.argv[1])
bag = out / "imu.bag"
bag.unlink(missing_ok=True)
ts = get_typestore(Stores.ROS1_NOETIC)
Imu = ts.types["sensor_msgs/msg/Imu"]
Header = ts.types["std_msgs/msg/Header"]
Time = ts.types["builtin_interfaces/msg/Time"]
Quaternion = ts.types["geometry_msgs/msg/Quaternion"]
Vector3 = ts.types["geometry_msgs/msg/Vector3"]
String = ts.types["std_msgs/msg/String"]
rows = []
with Writer(bag) as w:
    imu = w.add_connection("/imu", Imu.__msgtype__, typestore=ts)
    chat = w.add_connection("/chatter", String.__msgtype__, typestore=ts)
    for k in range(300):
        if k == 100:
            continue
        ns = 1_600_000_000 * 10**9 + 10_000_000 * k
        wx, wy, wz = 0.002 * k, -0.3, 0.05 * math.cos(k / 5)
        msg = Imu(
            header=Header(seq=k, stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id="imu" * (k % 3 + 1)),
            orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0),
            orientation_covariance=np.zeros(9),
            angular_velocity=Vector3(x=wx, y=wy, z=wz),
            angular_velocity_covariance=np.zeros(9),
            linear_acceleration=Vector3(x=0.0, y=0.0, z=9.81),
            linear_acceleration_covariance=np.zeros(9),
        )
        w.write(imu, ns, ts.serialize_ros1(msg, Imu.__msgtype__))
        if k % 50 == 0:
            w.write(chat, ns, ts.serialize_ros1(String(data="hi"), String.__msgtype__))
        rows.append(f"{ns / 1e9!r},{wx!r},{wy!r},{wz!r}")
(out / "expected.csv").write_text("t,x,y,z\n" + "\n".join(rows) + "\n")
