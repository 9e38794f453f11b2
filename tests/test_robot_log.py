"""systems.io.robot_log: a RobotLog through every format and back (CSV, Parquet, MCAP, ROS 1
bag, ROS 2 bag), topics of other rates aligned to the joint states, the topics YAML, and the
errors that name the problem."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from systems.io.robot_log import (
    LOG_FORMATS,
    RobotLog,
    load_topics,
    log_format,
    quaternion_to_rotation,
    read_log,
    resample_uniform,
    write_log,
)

FORMATS = {"csv": "log.csv", "parquet": "log.parquet", "mcap": "log.mcap", "ros1": "log.bag", "ros2": "log_ros2"}


def make_log(samples: int = 120, *, fsr: bool = False, seed: int = 0) -> RobotLog:
    rng = np.random.default_rng(seed)
    quaternion = rng.normal(size=(samples, 4))
    quaternion /= np.linalg.norm(quaternion, axis=1, keepdims=True)
    names = ("HIP_P", "KNEE_P", "L_HAND_J0")
    return RobotLog(
        time=12.5 + 0.001 * np.arange(samples),
        joint_names=names,
        joint_positions=rng.normal(size=(samples, 3)),
        joint_velocities=rng.normal(size=(samples, 3)),
        joint_torques=rng.normal(size=(samples, 3)),
        base_pose=np.hstack((quaternion, rng.normal(size=(samples, 3)))),
        base_velocity=rng.normal(size=(samples, 6)),
        wrenches={"L_FT_SENSOR_child": rng.normal(size=(samples, 6)), "r_ft": rng.normal(size=(samples, 6))},
        fsr_names=("l_front", "l_rear") if fsr else (),
        fsr_forces=rng.uniform(0, 10, size=(samples, 2)) if fsr else None,
        imu_angular_velocity=rng.normal(size=(samples, 3)),
        imu_linear_acceleration=rng.normal(size=(samples, 3)),
    )


def assert_logs_equal(a: RobotLog, b: RobotLog, atol: float = 0.0) -> None:
    assert a.joint_names == b.joint_names
    assert sorted(a.wrenches) == sorted(b.wrenches)
    np.testing.assert_allclose(a.time, b.time, rtol=0, atol=max(atol, 1e-9))
    for name in ("joint_positions", "joint_velocities", "joint_torques", "base_pose", "base_velocity"):
        assert (getattr(a, name) is None) == (getattr(b, name) is None), name
        if getattr(a, name) is not None:
            np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=0, atol=atol, err_msg=name)
    for name in ("imu_angular_velocity", "imu_linear_acceleration"):
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=0, atol=atol, err_msg=name)
    for frame in a.wrenches:
        np.testing.assert_allclose(a.wrenches[frame], b.wrenches[frame], rtol=0, atol=atol, err_msg=frame)


@pytest.mark.parametrize("kind", LOG_FORMATS)
def test_round_trip(tmp_path: Path, kind: str):
    log = make_log()
    path = write_log(log, tmp_path / FORMATS[kind])
    assert log_format(path) == kind
    back = read_log(path)
    # Tables keep every bit; ROS stamps are integer nanoseconds and the Odometry twist is
    # stored in the base frame (rotated there and back).
    assert_logs_equal(log, back, atol=0.0 if kind in ("csv", "parquet") else 1e-13)
    if kind in ("csv", "parquet"):
        np.testing.assert_array_equal(back.time, log.time)


@pytest.mark.parametrize("kind", ["csv", "parquet"])
def test_tables_keep_fsr_forces(tmp_path: Path, kind: str):
    log = make_log(fsr=True)
    back = read_log(write_log(log, tmp_path / FORMATS[kind]))
    assert back.fsr_names == ("l_front", "l_rear")
    np.testing.assert_array_equal(back.fsr_forces, log.fsr_forces)


def test_fsr_forces_have_no_ros_message(tmp_path: Path):
    with pytest.raises(ValueError, match="FSR forces have no standard ROS message"):
        write_log(make_log(fsr=True), tmp_path / "log.mcap")


def test_odometry_twist_is_rotated_between_base_and_world(tmp_path: Path):
    """A nav_msgs/Odometry twist is in the child (base) frame; RobotLog's base velocity is
    in the world: the message holds R_WB^T w."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    log = make_log(samples=5)
    path = write_log(log, tmp_path / "log.bag")
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS1_NOETIC)) as reader:
        connection = next(c for c in reader.connections if c.topic == "/odom")
        _, _, raw = next(reader.messages(connections=[connection]))
        twist = reader.deserialize(raw, connection.msgtype).twist.twist
    R = quaternion_to_rotation(log.base_pose[0, :4])
    np.testing.assert_allclose([twist.angular.x, twist.angular.y, twist.angular.z], R.T @ log.base_velocity[0, :3])
    np.testing.assert_allclose([twist.linear.x, twist.linear.y, twist.linear.z], R.T @ log.base_velocity[0, 3:])


def test_topics_yaml_maps_the_roles(tmp_path: Path):
    log = make_log()
    topics = {
        "joint_states": "/robot/joints",
        "odometry": "/robot/base",
        "imu": "/robot/imu",
        "wrenches": {"L_FT_SENSOR_child": "/ft/left", "r_ft": "/ft/right"},
    }
    path = write_log(log, tmp_path / "log.mcap", topics)
    with pytest.raises(ValueError, match="no joint-state topic '/joint_states'.*/robot/joints"):
        read_log(path)
    yaml = tmp_path / "topics.yaml"
    yaml.write_text(
        "joint_states: /robot/joints\nodometry: /robot/base\nimu: /robot/imu\n"
        "wrenches: {L_FT_SENSOR_child: /ft/left, r_ft: /ft/right}\n"
    )
    assert_logs_equal(log, read_log(path, yaml), atol=1e-13)
    # Without a wrench mapping every WrenchStamped topic is read, named by its frame_id.
    auto = read_log(path, {"joint_states": "/robot/joints", "odometry": "/robot/base", "imu": "/robot/imu"})
    assert sorted(auto.wrenches) == ["L_FT_SENSOR_child", "r_ft"]
    # A missing wrench topic is named.
    with pytest.raises(ValueError, match="no wrench topic '/ft/middle' for F/T frame 'm'"):
        read_log(path, {**topics, "wrenches": {"m": "/ft/middle"}})


def test_load_topics_errors(tmp_path: Path):
    assert load_topics(None)["joint_states"] == "/joint_states"
    with pytest.raises(ValueError, match=r"unknown topic roles \['joints'\]"):
        load_topics({"joints": "/j"})
    with pytest.raises(ValueError, match="'wrenches' must map F/T frame names to topic names"):
        load_topics({"wrenches": ["/a"]})
    bad = tmp_path / "bad.yaml"
    bad.write_text("joint_states: [unclosed\n")
    with pytest.raises(ValueError, match="cannot read the topics file"):
        load_topics(bad)


def _write_ros2_bag_at_two_rates(path: Path) -> None:
    """Joint states at 1 kHz, odometry at 200 Hz starting 2.5 ms later, IMU at 400 Hz; every
    signal linear in time, so linear interpolation is exact."""
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    T = store.types

    def header(t: float, frame: str = ""):
        ns = int(round(t * 1e9))
        return T["std_msgs/msg/Header"](
            stamp=T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9), frame_id=frame
        )

    def vec(x, y, z):
        return T["geometry_msgs/msg/Vector3"](x=x, y=y, z=z)

    with Writer(path, version=9) as writer:
        joints = writer.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=store)
        odom = writer.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=store)
        imu = writer.add_connection("/imu/data", "sensor_msgs/msg/Imu", typestore=store)
        for k in range(100):
            t = 1.0 + 0.001 * k
            msg = T["sensor_msgs/msg/JointState"](
                header=header(t), name=["a"], position=np.array([t]), velocity=np.array([2 * t]), effort=np.array([3.0])
            )
            writer.write(joints, int(round(t * 1e9)), store.serialize_cdr(msg, msg.__msgtype__))
        for k in range(21):
            t = 1.0025 + 0.005 * k
            pose = T["geometry_msgs/msg/Pose"](
                position=T["geometry_msgs/msg/Point"](x=t, y=0.0, z=0.5),
                orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
            )
            msg = T["nav_msgs/msg/Odometry"](
                header=header(t, "world"),
                child_frame_id="base",
                pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
                twist=T["geometry_msgs/msg/TwistWithCovariance"](
                    twist=T["geometry_msgs/msg/Twist"](linear=vec(1.0, 0.0, 0.0), angular=vec(0.0, 0.0, t)),
                    covariance=np.zeros(36),
                ),
            )
            writer.write(odom, int(round(t * 1e9)), store.serialize_cdr(msg, msg.__msgtype__))
        for k in range(41):
            t = 1.0 + 0.0025 * k
            msg = T["sensor_msgs/msg/Imu"](
                header=header(t, "imu"),
                orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                orientation_covariance=np.zeros(9),
                angular_velocity=vec(t, 0.0, 0.0),
                angular_velocity_covariance=np.zeros(9),
                linear_acceleration=vec(0.0, 0.0, 9.81 + t),
                linear_acceleration_covariance=np.zeros(9),
            )
            writer.write(imu, int(round(t * 1e9)), store.serialize_cdr(msg, msg.__msgtype__))


def test_topics_of_other_rates_are_aligned_to_the_joint_states(tmp_path: Path):
    path = tmp_path / "rates"
    _write_ros2_bag_at_two_rates(path)
    log = read_log(path)
    # Joint samples before the first odometry stamp (1.0025 s) and after its last (1.1025 s)
    # are dropped, not extrapolated: 1.003 .. 1.099 s.
    np.testing.assert_allclose(log.time[[0, -1]], [1.003, 1.099], atol=1e-9)
    assert log.num_samples == 97
    np.testing.assert_allclose(log.joint_positions[:, 0], log.time, atol=1e-9)
    np.testing.assert_allclose(log.base_pose[:, 4], log.time, atol=1e-9)  # x = t at 200 Hz
    np.testing.assert_allclose(log.base_velocity[:, 2], log.time, atol=1e-9)  # w_z = t
    np.testing.assert_allclose(log.imu_angular_velocity[:, 0], log.time, atol=1e-9)
    np.testing.assert_allclose(log.imu_linear_acceleration[:, 2], 9.81 + log.time, atol=1e-9)


def _streams(imu_stamps, wrench_stamps, joint_stamps):
    """The streams ``_streams_to_log`` merges: one joint "a" (q = t), an IMU (gyro x = t) and
    one F/T wrench (fz = t), each at its own stamps."""
    from systems.io.robot_log import _Stream

    streams = {"joint_states": _Stream("/joint_states"), "imu": _Stream("/imu/data")}
    streams[("wrench", None, "/ft/left")] = _Stream("/ft/left")
    streams["joint_states"].names = ("a",)
    streams[("wrench", None, "/ft/left")].names = ("l_ft",)
    for key, stamps, row in (
        ("joint_states", joint_stamps, lambda t: [t, 1.0, 0.0]),
        ("imu", imu_stamps, lambda t: [t, 0.0, 0.0, 0.0, 0.0, 9.81]),
        (("wrench", None, "/ft/left"), wrench_stamps, lambda t: [0.0, 0.0, 0.0, 0.0, 0.0, t]),
    ):
        streams[key].stamps = list(stamps)
        streams[key].rows = [np.array(row(t)) for t in stamps]
    return streams


def test_a_gap_inside_a_topic_is_refused_naming_it():
    """A gap longer than 5 median periods in the IMU or a wrench topic, inside the joint
    states' span, was silently interpolated across: it is refused naming the topic and the
    time; gaps of up to 5 periods are interpolated, and a topic's gap outside the joint
    states' span (its samples dropped) is not an error."""
    from systems.io.robot_log import MAX_TOPIC_GAP_PERIODS, _streams_to_log

    roles = load_topics(None)
    joints = 1.0 + 0.001 * np.arange(200)
    imu = 1.0 + 0.0025 * np.arange(81)
    wrench = 1.0 + 0.001 * np.arange(200)
    log = _streams_to_log(_streams(imu, wrench, joints), roles, Path("x.mcap"))
    np.testing.assert_allclose(log.imu_angular_velocity[:, 0], log.time, atol=1e-12)
    # IMU messages missing from 1.1 s to 1.12 s: 0.0225 s = 9 periods of 2.5 ms.
    holed = imu[(imu <= 1.1 + 1e-9) | (imu >= 1.1225 - 1e-9)]
    with pytest.raises(
        ValueError,
        match=r"topic /imu/data has a gap of 0\.0225 s after t = 1\.1 s \(1 gap\(s\) longer than 5 "
        r"times its median period of 0\.0025 s\) inside the joint states' time span",
    ):
        _streams_to_log(_streams(holed, wrench, joints), roles, Path("x.mcap"))
    # A wrench topic: 7 ms without a message after 1.05 s.
    holed = wrench[(wrench <= 1.05 + 1e-9) | (wrench >= 1.057 - 1e-9)]
    with pytest.raises(ValueError, match=r"topic /ft/left has a gap of 0\.007 s after t = 1\.05 s"):
        _streams_to_log(_streams(imu, holed, joints), roles, Path("x.mcap"))
    # Exactly 5 periods: interpolated (linear data: exactly).
    short = wrench[(wrench <= 1.05 + 1e-9) | (wrench >= 1.055 - 1e-9)]
    assert MAX_TOPIC_GAP_PERIODS == 5.0
    log = _streams_to_log(_streams(imu, short, joints), roles, Path("x.mcap"))
    np.testing.assert_allclose(log.wrenches["l_ft"][:, 5], log.time, atol=1e-9)
    # A gap in the IMU before the joint states start is outside their span: not an error.
    early = np.concatenate(([0.5], imu))
    log = _streams_to_log(_streams(early, wrench, joints), roles, Path("x.mcap"))
    assert log.num_samples == 200


def test_a_gap_inside_a_topic_of_a_bag_is_refused(tmp_path: Path):
    """The same through a file: an MCAP whose IMU topic lacks 20 ms of messages."""
    log = make_log(samples=120)
    path = write_log(log, tmp_path / "log.mcap")
    from mcap.reader import make_reader
    from mcap.writer import Writer

    holed = tmp_path / "holed.mcap"
    with open(path, "rb") as source, open(holed, "wb") as target:
        reader = make_reader(source)
        summary = reader.get_summary()
        writer = Writer(target)
        writer.start(profile="ros2", library="test")
        schemas = {i: writer.register_schema(s.name, s.encoding, s.data) for i, s in summary.schemas.items()}
        channels = {
            i: writer.register_channel(c.topic, c.message_encoding, schemas[c.schema_id])
            for i, c in summary.channels.items()
        }
        for _, channel, message in reader.iter_messages():
            if channel.topic == "/imu/data" and 12_540_000_000 < message.log_time < 12_560_000_000:
                continue
            writer.add_message(channels[channel.id], message.log_time, message.data, message.publish_time)
        writer.finish()
    with pytest.raises(ValueError, match=r"topic /imu/data has a gap of 0\.02 s after t = 12\.54 s"):
        read_log(holed)


def test_resample_uniform():
    log = make_log(samples=50)
    jittered = log.select(slice(None))
    jittered.time = log.time + np.where(np.arange(50) % 2, 2e-4, 0.0)
    uniform = resample_uniform(jittered, 0.001)
    np.testing.assert_allclose(np.diff(uniform.time), 0.001, atol=1e-12)
    assert uniform.num_samples == 50
    np.testing.assert_allclose(np.linalg.norm(uniform.base_pose[:, :4], axis=1), 1.0)
    with pytest.raises(ValueError, match="period must be a positive number"):
        resample_uniform(log, 0.0)


def test_stamp_timing_tells_stamp_noise_from_uneven_sampling():
    """Known answers: uniform stamps; rows evenly spaced every 1 ms with stamps +-0.1 ms off
    (stamp noise: fitted period 1 ms, jitter 0.1 ms RMS); one row missing (uneven: the
    stamps after it are a whole period off the line); a rate drifting by 0.1 % along 1000
    rows with the same stamp noise (uneven: the deviations are not zero-mean block by
    block) though each stamp stays within a quarter period of the line."""
    from systems.io.robot_log import stamp_timing

    rows = np.arange(400)
    uniform = stamp_timing(3.0 + 1e-3 * rows)
    assert uniform.case == "uniform" and uniform.period == pytest.approx(1e-3) and uniform.jitter_rms < 1e-12
    noisy = stamp_timing(3.0 + 1e-3 * rows + 1e-4 * np.where(rows % 2, 1.0, -1.0))
    assert noisy.case == "stamp noise"
    assert noisy.period == noisy.fitted_period == pytest.approx(1e-3, rel=1e-5)
    assert noisy.jitter_rms == pytest.approx(1e-4, rel=1e-3)
    np.testing.assert_allclose(noisy.fitted_stamps(400), 3.0 + 1e-3 * rows, rtol=0, atol=2e-6)
    dropped = stamp_timing(3.0 + 1e-3 * np.delete(np.arange(401), 200))
    assert dropped.case == "uneven" and dropped.period == pytest.approx(1e-3)
    rows = np.arange(1000)
    drifting = 3.0 + np.concatenate(([0.0], np.cumsum(1e-3 * (1.0 + 1e-3 * np.linspace(-0.5, 0.5, 999)))))
    timing = stamp_timing(drifting + 1e-4 * np.where(rows % 2, 1.0, -1.0))
    assert timing.max_deviation < 0.25 * timing.fitted_period and timing.case == "uneven"
    assert stamp_timing(3.0 + 1e-3 * rows + 1e-4 * np.where(rows % 2, 1.0, -1.0)).case == "stamp noise"


# -- errors -------------------------------------------------------------------------------


def test_unknown_extension_and_missing_file(tmp_path: Path):
    with pytest.raises(ValueError, match=r"unknown log format '\.txt'"):
        read_log(tmp_path / "log.txt")
    with pytest.raises(ValueError, match="unknown log format"):
        write_log(make_log(), tmp_path / "log.h5")
    with pytest.raises(ValueError, match="does not exist"):
        read_log(tmp_path / "missing.csv")
    (tmp_path / "folder").mkdir()
    with pytest.raises(ValueError, match="without metadata.yaml: not a ROS 2 bag"):
        read_log(tmp_path / "folder")


@pytest.mark.parametrize("name", ["log.parquet", "log.mcap", "log.bag", "log.csv"])
def test_unreadable_file(tmp_path: Path, name: str):
    path = tmp_path / name
    path.write_bytes(b"\x00\x01 this is not a log \xff" * 10)
    with pytest.raises(ValueError, match="cannot read|not numeric|no 'time' column"):
        read_log(path)


def test_missing_and_unknown_columns(tmp_path: Path):
    import pyarrow as pa
    import pyarrow.csv as csv

    path = write_log(make_log(), tmp_path / "log.csv")
    table = csv.read_csv(path)
    csv.write_csv(table.drop_columns(["v_KNEE_P", "wrench_r_ft_fz"]), tmp_path / "missing.csv")
    with pytest.raises(ValueError, match=r"missing column\(s\) \['v_KNEE_P', 'wrench_r_ft_fz'\]"):
        read_log(tmp_path / "missing.csv")
    csv.write_csv(table.drop_columns(["base_qw"]), tmp_path / "base.csv")
    with pytest.raises(ValueError, match=r"missing column\(s\) \['base_qw'\]"):
        read_log(tmp_path / "base.csv")
    csv.write_csv(table.append_column("qq_HIP", pa.array(np.zeros(table.num_rows))), tmp_path / "typo.csv")
    with pytest.raises(ValueError, match=r"unknown column\(s\) \['qq_HIP'\]"):
        read_log(tmp_path / "typo.csv")
    csv.write_csv(table.drop_columns(["time"]), tmp_path / "notime.csv")
    with pytest.raises(ValueError, match="no 'time' column"):
        read_log(tmp_path / "notime.csv")


def test_nan_in_a_sensor_is_named(tmp_path: Path):
    log = make_log()
    log.wrenches["r_ft"][37, 4] = np.nan
    path = write_log(log, tmp_path / "log.parquet")  # writing does not check: a foreign file may hold NaN
    with pytest.raises(ValueError, match=r"NaN in wrenches\['r_ft'\] \(channel 'fy'\) at sample 37 \(t = 12.537"):
        read_log(path)
    torques = make_log().joint_torques
    torques[3, 1] = np.inf
    with pytest.raises(ValueError, match=r"inf in joint_torques \(channel 'KNEE_P'\) at sample 3"):
        zeros = np.zeros_like(torques)
        RobotLog(np.arange(120) * 1e-3, ("a", "KNEE_P", "c"), zeros, zeros, torques)


def test_non_increasing_time(tmp_path: Path):
    log = make_log()
    table_path = write_log(log, tmp_path / "log.csv")
    text = table_path.read_text().splitlines()
    text[6], text[7] = text[7], text[6]  # samples 5 and 6 swapped
    table_path.write_text("\n".join(text) + "\n")
    with pytest.raises(
        ValueError, match=r"time is not strictly increasing at sample 6 \(t = 12.506 s, then 12.505 s\)"
    ):
        read_log(table_path)


def test_constructor_checks():
    good = make_log()
    with pytest.raises(ValueError, match=r"joint_velocities must have shape \(120, 3\)"):
        RobotLog(good.time, good.joint_names, good.joint_positions, good.joint_velocities[:, :2], good.joint_torques)
    with pytest.raises(ValueError, match=r"duplicate joint names \['a'\]"):
        RobotLog(good.time, ("a", "a", "b"), good.joint_positions, good.joint_velocities, good.joint_torques)
    pose = good.base_pose.copy()
    pose[10, :4] *= 2.0
    with pytest.raises(ValueError, match="quaternion .* has norm 2 at t = 12.51"):
        RobotLog(good.time, good.joint_names, good.joint_positions, good.joint_velocities, good.joint_torques, pose)
    with pytest.raises(ValueError, match="fsr_forces and fsr_names go together"):
        RobotLog(
            good.time,
            good.joint_names,
            good.joint_positions,
            good.joint_velocities,
            good.joint_torques,
            fsr_forces=np.zeros((120, 2)),
        )


def _write_joint_states_bag(path: Path, efforts: list, velocity: bool = True) -> None:
    """A ROS 1 bag of JointState messages of one joint "a", one per entry of ``efforts``
    (each an effort array: [] for none), 1 ms apart."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    T = store.types
    with Writer(path) as writer:
        connection = writer.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=store)
        for k, effort in enumerate(efforts):
            header = T["std_msgs/msg/Header"](
                seq=k, stamp=T["builtin_interfaces/msg/Time"](sec=0, nanosec=1000000 * k), frame_id=""
            )
            msg = T["sensor_msgs/msg/JointState"](
                header=header,
                name=["a"],
                position=np.array([0.1 * k]),
                velocity=np.array([0.2 * k] if velocity else []),
                effort=np.array(effort, dtype=float),
            )
            writer.write(connection, k * 1000000, store.serialize_ros1(msg, msg.__msgtype__))


def test_joint_states_without_effort_are_read_without_torques(tmp_path: Path):
    """A JointState without effort (a robot that logs no joint torques) is read with
    ``joint_torques`` None and its positions and velocities; effort in some messages only,
    or no velocity, is refused naming the problem."""
    path = tmp_path / "no_effort.bag"
    _write_joint_states_bag(path, [[], [], []])
    log = read_log(path)
    assert log.joint_torques is None and log.joint_names == ("a",)
    np.testing.assert_allclose(log.joint_positions[:, 0], [0.0, 0.1, 0.2])
    np.testing.assert_allclose(log.joint_velocities[:, 0], [0.0, 0.2, 0.4])
    np.testing.assert_allclose(log.time, [0.0, 0.001, 0.002])
    with_effort = tmp_path / "effort.bag"
    _write_joint_states_bag(with_effort, [[1.0], [2.0], [3.0]])
    np.testing.assert_array_equal(read_log(with_effort).joint_torques[:, 0], [1.0, 2.0, 3.0])
    mixed = tmp_path / "mixed.bag"
    _write_joint_states_bag(mixed, [[1.0], [], [3.0]])
    with pytest.raises(ValueError, match="effort in some messages and none in others"):
        read_log(mixed)
    no_velocity = tmp_path / "no_velocity.bag"
    _write_joint_states_bag(no_velocity, [[], [], []], velocity=False)
    with pytest.raises(ValueError, match="has 0 velocity values for 1 joints"):
        read_log(no_velocity)


@pytest.mark.parametrize("kind", LOG_FORMATS)
def test_a_log_without_torques_round_trips(tmp_path: Path, kind: str):
    """Without joint torques: no tau_ columns in a table, JointState effort empty in ROS;
    read back with ``joint_torques`` None. A table with some tau_ columns only is refused."""
    log = replace(make_log(), joint_torques=None)
    path = write_log(log, tmp_path / FORMATS[kind])
    if kind == "csv":
        assert not [c for c in path.read_text().splitlines()[0].split(",") if c.startswith("tau_")]
    back = read_log(path)
    assert_logs_equal(log, back, atol=1e-9)
    assert log.select(slice(0, 10)).joint_torques is None
    assert resample_uniform(log, 0.0015).joint_torques is None
    if kind == "csv":
        partial = tmp_path / "partial.csv"
        write_log(replace(make_log(), joint_torques=make_log().joint_torques), partial)
        lines = partial.read_text().splitlines()
        header = lines[0].split(",")
        drop = header.index('"tau_KNEE_P"') if '"tau_KNEE_P"' in header else header.index("tau_KNEE_P")
        partial.write_text("\n".join(",".join(c for i, c in enumerate(line.split(",")) if i != drop) for line in lines))
        with pytest.raises(ValueError, match="missing column.*tau_KNEE_P"):
            read_log(partial)


@pytest.mark.parametrize("kind", ("csv", "parquet"))
def test_normal_force_only_feet_round_trip_in_tables(tmp_path: Path, kind: str):
    """A foot that logs only its normal force: its ``wrench_<frame>_fz`` column alone, read
    back as ``normal_forces``; another frame with a partial wrench is still refused; ROS
    formats refuse normal-force-only feet (no standard message)."""
    full = make_log()
    log = replace(
        full,
        wrenches={"r_ft": full.wrenches["r_ft"]},
        normal_forces={"L_FT_SENSOR_child": full.wrenches["L_FT_SENSOR_child"][:, 5]},
    )
    path = write_log(log, tmp_path / f"log.{kind}")
    back = read_log(path)
    assert sorted(back.wrenches) == ["r_ft"] and sorted(back.normal_forces) == ["L_FT_SENSOR_child"]
    np.testing.assert_array_equal(back.normal_forces["L_FT_SENSOR_child"], log.normal_forces["L_FT_SENSOR_child"])
    np.testing.assert_array_equal(
        back.select(slice(2, 5)).normal_forces["L_FT_SENSOR_child"], log.normal_forces["L_FT_SENSOR_child"][2:5]
    )
    with pytest.raises(ValueError, match="normal-force-only feet .* have no standard ROS message"):
        write_log(log, tmp_path / "log.mcap")
    with pytest.raises(ValueError, match="both a wrench and a normal force"):
        replace(full, normal_forces={"r_ft": full.wrenches["r_ft"][:, 5]})
    with pytest.raises(ValueError, match=r"NaN in normal_forces\['L_FT_SENSOR_child'\]"):
        replace(log, normal_forces={"L_FT_SENSOR_child": np.full(full.num_samples, np.nan)})
