#!/usr/bin/env python3
"""A ROS 2 bag of `sensor_msgs/msg/Imu`, in MCAP and in sqlite3 storage,
written by the `rosbags` library (not by this project), the fixtures of
`gyro_tool::ros2` (tests `an_imu_topic_reads_as_rosbags_wrote_it`,
`a_sqlite3_bag_reads_as_its_mcap_twin`).

    python3 -m venv /tmp/v && /tmp/v/bin/pip install rosbags==0.11.9
    /tmp/v/bin/python gyro-tool/tests/vectors/ros2/make_bag.py gyro-tool/tests/vectors/ros2

Writes `imu_bag/` (metadata.yaml and imu_bag.mcap) and `imu_bag_db3/`
(metadata.yaml and imu_bag_db3.db3, the same messages): topic `/imu/data`,
400 messages at 200 Hz (angular velocity x, y, z = 0.01·sin(k/7),
−0.02 + 1e-4·k, 0.5 rad/s; header stamps 1 700 000 000 s + 5 ms·k, except
a dropped message at k = 250, so the stamps have one gap), and topic
`/other` (a `std_msgs/msg/String`, to be skipped); and `expected.csv`:
the stamps (s) and rates (rad/s) as written.
"""
import math
import shutil
import sys
from pathlib import Path

from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

out = Path(sys.argv[1])
bag = out / "imu_bag"
shutil.rmtree(bag, ignore_errors=True)
ts = get_typestore(Stores.ROS2_HUMBLE)
Imu = ts.types["sensor_msgs/msg/Imu"]
Header = ts.types["std_msgs/msg/Header"]
Time = ts.types["builtin_interfaces/msg/Time"]
Quaternion = ts.types["geometry_msgs/msg/Quaternion"]
Vector3 = ts.types["geometry_msgs/msg/Vector3"]
String = ts.types["std_msgs/msg/String"]
import numpy as np


def write(bag, plugin):
    rows = []
    with Writer(bag, version=9, storage_plugin=plugin) as w:
        imu = w.add_connection("/imu/data", Imu.__msgtype__, typestore=ts)
        other = w.add_connection("/other", String.__msgtype__, typestore=ts)
        for k in range(400):
            if k == 250:
                continue
            ns = 1_700_000_000 * 10**9 + 5_000_000 * k
            wx, wy, wz = 0.01 * math.sin(k / 7), -0.02 + 1e-4 * k, 0.5
            msg = Imu(
                header=Header(stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id="imu_link"),
                orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0),
                orientation_covariance=np.zeros(9),
                angular_velocity=Vector3(x=wx, y=wy, z=wz),
                angular_velocity_covariance=np.zeros(9),
                linear_acceleration=Vector3(x=0.0, y=0.0, z=9.81),
                linear_acceleration_covariance=np.zeros(9),
            )
            w.write(imu, ns, ts.serialize_cdr(msg, Imu.__msgtype__))
            if k % 100 == 0:
                w.write(other, ns, ts.serialize_cdr(String(data="hello"), String.__msgtype__))
            rows.append(f"{ns / 1e9!r},{wx!r},{wy!r},{wz!r}")
    return rows


rows = write(bag, StoragePlugin.MCAP)
db3 = out / "imu_bag_db3"
shutil.rmtree(db3, ignore_errors=True)
assert write(db3, StoragePlugin.SQLITE3) == rows
(out / "expected.csv").write_text("t,x,y,z\n" + "\n".join(rows) + "\n")
