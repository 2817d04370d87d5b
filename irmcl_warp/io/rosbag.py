"""ROS1 and ROS2 bags through ``rosbags``: sensor_msgs/LaserScan + nav_msgs/Odometry (or /tf) + /tf_static.

Reading follows ROS conventions: scans ordered by header stamp (as ROS tools replay them); a beam that is
NaN, +-inf, below range_min or above range_max is "no return" (REP 117) and becomes NaN. The recording
order comes from ``header.seq`` (ROS1): stamps that go backwards in it are counted, not "fixed".
Odometry is interpolated at the scan stamps. The base->laser extrinsic is read from /tf_static.
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from irmcl_warp.geometry import interpolate_poses
from irmcl_warp.io.beams import BeamPolicy, check_geometry, harmonise_beams
from irmcl_warp.io.defects import count_stamps_backwards, count_velocity_contradictions, repair_reversing, scan_defects
from irmcl_warp.io.errors import LogFormatError, warn_defects
from irmcl_warp.types import DefectReport, LaserInfo, LaserLog, match_stamps

SCAN, ODOM, TF = "sensor_msgs/msg/LaserScan", "nav_msgs/msg/Odometry", "tf2_msgs/msg/TFMessage"
GROUND_TRUTH_TOPIC = "/ground_truth"  # nav_msgs/Odometry of the base in the world (the simulator's bags): read as truth
IMAGE = "sensor_msgs/msg/Image"


@dataclass
class CameraFrames:
    stamps: np.ndarray  # [F] s
    rgb: np.ndarray  # [F, H, W, 3] uint8
    depth: np.ndarray  # [F, H, W] float32 metres (0 = none)
    depth_encoding: str = "32FC1"  # 32FC1 (metres) | 16UC1 (millimetres)


def _encode(img: np.ndarray, enc: str) -> tuple[np.ndarray, int]:
    if enc == "rgb8":
        a = np.ascontiguousarray(img, np.uint8)
    elif enc == "32FC1":
        a = np.ascontiguousarray(img, "<f4")
    elif enc == "16UC1":
        a = np.ascontiguousarray(np.clip(np.round(np.nan_to_num(img) * 1000.0), 0, 65535), "<u2")
    else:
        raise ValueError(f"image encoding {enc!r}: write rgb8, 32FC1 or 16UC1")
    return np.frombuffer(a.tobytes(), np.uint8), a.strides[0]


def _decode(path, where, msg) -> np.ndarray:
    h, w, enc = int(msg.height), int(msg.width), msg.encoding
    kinds = {"rgb8": (np.uint8, 3), "bgr8": (np.uint8, 3), "32FC1": (np.dtype("<f4"), 1), "16UC1": (np.dtype("<u2"), 1)}
    if enc not in kinds:
        raise LogFormatError(path, where, f"image encoding {enc!r}: expected one of {sorted(kinds)}")
    dt, ch = kinds[enc]
    need = h * w * ch * np.dtype(dt).itemsize
    buf = np.asarray(msg.data, np.uint8)
    if int(msg.step) < w * ch * np.dtype(dt).itemsize or buf.size < int(msg.step) * h:
        raise LogFormatError(
            path, where, f"image of {w} x {h} {enc} needs {need} bytes, has {buf.size} (step {msg.step})"
        )
    rows = buf[: int(msg.step) * h].reshape(h, int(msg.step))[:, : w * ch * np.dtype(dt).itemsize]
    a = (
        np.frombuffer(rows.tobytes(), dt).reshape(h, w, ch)
        if ch == 3
        else np.frombuffer(rows.tobytes(), dt).reshape(h, w)
    )
    if enc == "bgr8":
        a = a[..., ::-1]
    if enc == "16UC1":
        return a.astype(np.float32) / 1000.0
    return a.astype(np.float32) if ch == 1 else a.copy()


def read_bag_images(path, rgb_topic: str = "/camera/rgb", depth_topic: str = "/camera/depth") -> CameraFrames:
    """Camera frames of a bag: RGB and depth sensor_msgs/Image paired by header stamp (frames with both)."""
    from rosbags.highlevel import AnyReader

    path = Path(path)
    rgb, depth = {}, {}
    try:
        with AnyReader([path]) as reader:
            conns = [c for c in reader.connections if c.topic in (rgb_topic, depth_topic)]
            if {c.topic for c in conns} != {rgb_topic, depth_topic}:
                raise LogFormatError(
                    path,
                    None,
                    f"expected image topics {rgb_topic} and {depth_topic}, found "
                    f"{sorted({c.topic for c in reader.connections if c.msgtype == IMAGE})}",
                )
            for k, (conn, _, raw) in enumerate(reader.messages(connections=conns)):
                msg = reader.deserialize(raw, conn.msgtype)
                img = _decode(path, f"message {k} on {conn.topic}", msg)
                (rgb if conn.topic == rgb_topic else depth)[round(_stamp(msg.header), 6)] = img
    except LogFormatError:
        raise
    except Exception as e:
        raise LogFormatError(path, None, f"cannot read images: {e}") from e
    both = sorted(set(rgb) & set(depth))
    if not both:
        raise LogFormatError(path, None, f"no frame has both {rgb_topic} and {depth_topic}")
    return CameraFrames(np.array(both), np.stack([rgb[t] for t in both]), np.stack([depth[t] for t in both]))


def _stamp(header) -> float:
    return header.stamp.sec + header.stamp.nanosec * 1e-9


class _Quaternions:
    """Checks every orientation read: a quaternion that is not finite or has (almost) no length names no
    rotation and is an error; one that is off unit length is normalised and counted."""

    def __init__(self):
        self.unnormalised = 0

    def yaw(self, q, path, where) -> float:
        v = np.array([q.x, q.y, q.z, q.w], np.float64)
        norm = float(np.linalg.norm(v)) if np.all(np.isfinite(v)) else float("nan")
        if not norm > 1e-6:
            raise LogFormatError(
                path, where, f"quaternion ({q.x}, {q.y}, {q.z}, {q.w}) is no rotation: expected unit length"
            )
        if abs(norm - 1.0) > 1e-3:
            self.unnormalised += 1
        x, y, z, w = v / norm if abs(norm - 1.0) > 1e-6 else v  # unit to float precision: read as written
        return float(np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)))


@dataclass
class _Streams:
    scans: list  # (stamp, seq, ranges, angle_min, angle_inc, range_min, range_max, frame, index)
    odom: list  # (stamp, seq, x, y, yaw, v)
    tf: list  # (stamp, parent, child, x, y, yaw)
    tf_static: list  # (parent, child, x, y, yaw)
    path: Path = Path()
    quats: _Quaternions = None
    truth: list = field(default_factory=list)  # (stamp, x, y, yaw) on GROUND_TRUTH_TOPIC

    def yaw(self, q, where) -> float:
        return self.quats.yaw(q, self.path, where)


def _pick_topic(path, conns, msgtype, wanted):
    topics = sorted({c.topic for c in conns if c.msgtype == msgtype})
    if wanted:
        if wanted not in {c.topic for c in conns}:
            raise LogFormatError(path, None, f"topic {wanted!r} not in bag (has {sorted({c.topic for c in conns})})")
        return wanted
    if len(topics) > 1:
        raise LogFormatError(
            path, None, f"several {msgtype} topics {topics}: choose one (data.scan_topic / data.odom_topic)"
        )
    return topics[0] if topics else None


def _read_streams(path: Path, scan_topic, odom_topic) -> tuple[_Streams, str, str | None]:
    from rosbags.highlevel import AnyReader

    s = _Streams([], [], [], [], path, _Quaternions())
    try:
        reader = AnyReader([path])
        reader.open()
    except Exception as e:  # rosbags raises several reader errors for truncated or foreign files
        raise LogFormatError(path, None, f"cannot open as a ROS1/ROS2 bag: {e}") from e
    try:
        scan_topic = _pick_topic(path, reader.connections, SCAN, scan_topic)
        if scan_topic is None:
            raise LogFormatError(
                path, None, f"no {SCAN} topic (topics: {sorted({c.topic for c in reader.connections})})"
            )
        odom_topic = _pick_topic(
            path, [c for c in reader.connections if c.topic != GROUND_TRUTH_TOPIC], ODOM, odom_topic
        )
        truth = (
            GROUND_TRUTH_TOPIC
            if any(c.topic == GROUND_TRUTH_TOPIC and c.msgtype == ODOM for c in reader.connections)
            else None
        )
        conns = [c for c in reader.connections if c.topic in (scan_topic, odom_topic, truth) or c.msgtype == TF]
        counters: dict[str, int] = {}
        messages = reader.messages(connections=conns)
        from tqdm import tqdm

        bar = tqdm(
            total=sum(c.msgcount for c in conns),
            desc=f"read {path.name}",
            unit="msg",
            mininterval=1.0,
            disable=None,
            leave=False,
        )  # (on a terminal only)
        while True:
            try:
                conn, _, raw = next(messages)
                bar.update()
            except StopIteration:
                bar.close()
                break
            except Exception as e:
                raise LogFormatError(
                    path, f"after message {sum(counters.values())}", f"bag is truncated or corrupt: {e}"
                ) from e
            k = counters[conn.topic] = counters.get(conn.topic, -1) + 1
            try:
                msg = reader.deserialize(raw, conn.msgtype)
            except Exception as e:
                raise LogFormatError(
                    path, f"message {k} on {conn.topic}", f"cannot deserialize {conn.msgtype}: {e}"
                ) from e
            _collect(s, conn, msg, scan_topic, odom_topic, k)
    finally:
        reader.close()
    return s, scan_topic, odom_topic


def _collect(s: _Streams, conn, msg, scan_topic, odom_topic, k):
    if conn.topic == scan_topic:
        s.scans.append(
            (
                _stamp(msg.header),
                getattr(msg.header, "seq", k),
                np.asarray(msg.ranges, dtype=np.float64),
                msg.angle_min,
                msg.angle_increment,
                msg.range_min,
                msg.range_max,
                msg.header.frame_id,
                k,
            )
        )
    elif conn.topic == GROUND_TRUTH_TOPIC and conn.msgtype == ODOM:
        p = msg.pose.pose
        s.truth.append(
            (_stamp(msg.header), p.position.x, p.position.y, s.yaw(p.orientation, f"message {k} on {conn.topic}"))
        )
    elif conn.topic == odom_topic:
        p = msg.pose.pose
        s.odom.append(
            (
                _stamp(msg.header),
                getattr(msg.header, "seq", k),
                p.position.x,
                p.position.y,
                s.yaw(p.orientation, f"message {k} on {conn.topic}"),
                msg.twist.twist.linear.x,
            )
        )
    elif conn.msgtype == TF:
        for t in msg.transforms:
            tr, q = t.transform.translation, t.transform.rotation
            row = (
                t.header.frame_id.lstrip("/"),
                t.child_frame_id.lstrip("/"),
                tr.x,
                tr.y,
                s.yaw(q, f"message {k} on {conn.topic}"),
            )
            if conn.topic == "/tf_static":
                s.tf_static.append(row)
            else:
                s.tf.append((_stamp(t.header),) + row)


def _recording_order(stamps, seqs):
    """Indices in recording order: by header.seq where it is a usable counter, else as read."""
    seqs = np.asarray(seqs)
    if len(np.unique(seqs)) == len(seqs) and seqs.any():
        return np.argsort(seqs, kind="stable")
    return np.arange(len(stamps))


def read_bag(
    path,
    *,
    scan_topic: str | None = None,
    odom_topic: str | None = None,
    base_frame: str | None = None,
    odom_frame: str | None = None,
    beam_policy: BeamPolicy = "error",
    max_speed_mps: float = 3.0,
    max_step_m: float = 2.0,
    repair_reversing: bool = False,
    scan_time_offset_s: float = 0.0,
) -> LaserLog:
    """``repair_reversing``: drive backwards the odometry steps whose messages report a negative forward
    velocity (io.defects.repair_reversing); the repair is counted in the log's defects."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such bag")
    s, scan_topic, odom_topic = _read_streams(path, scan_topic, odom_topic)
    if not s.scans:
        raise LogFormatError(path, None, f"topic {scan_topic} holds no messages")
    report = DefectReport()
    report.add("quaternions_not_unit", s.quats.unnormalised, "orientations off unit length by > 1e-3, normalised")
    stamps_read = np.array([r[0] for r in s.scans])
    rec = _recording_order(stamps_read, [r[1] for r in s.scans])
    report.add(
        "scans_stamps_backwards",
        count_stamps_backwards(stamps_read[rec]),
        "scans stamped earlier than the scan recorded before them (header.seq order)",
    )
    order = np.argsort(stamps_read, kind="stable")
    scans = [s.scans[i] for i in order]
    where = [f"message {r[8]} on {scan_topic}" for r in scans]
    geometries = [check_geometry(path, w, len(r[2]), r[3], r[4], r[5], r[6]) for w, r in zip(where, scans)]
    ranges, kept, common = harmonise_beams(path, [r[2] for r in scans], where, beam_policy, report, geometries)
    scans = [scans[i] for i in kept]
    first = scans[0]
    # each scan's own limits mask its own beams (drivers write range_max for "no echo" too)
    rmin = np.array([float(r[5]) for r in scans])[:, None]
    rmax = np.array([float(r[6]) for r in scans])[:, None]
    report.add(
        "scans_with_other_range_limits",
        int(np.sum((rmin != rmin[0]) | (rmax != rmax[0]))),
        f"scans whose range_min/range_max differ from the first scan's {rmin[0, 0]:g}/{rmax[0, 0]:g} m",
    )
    finite = np.isfinite(ranges)
    beyond = float(np.max(ranges[finite])) if finite.any() else float(rmax.max())
    with np.errstate(invalid="ignore"):
        bad = ~finite | (ranges < rmin) | (ranges >= rmax) | (ranges == 0)
        report.add(
            "beams_below_range_min",
            int(np.sum(finite & (ranges < rmin) & (ranges != 0))),
            "beams below range_min, masked",
        )
        report.add(
            "zero_ranges",
            int(np.sum(ranges == 0)),
            "beams reading 0 m (a driver's no echo, even where range_min is 0), masked as no return",
        )
    ranges = np.where(bad, np.nan, ranges).astype(np.float32)
    rmin0, rmax0 = float(np.median(rmin)), float(np.median(rmax))
    info = LaserInfo(
        common.num_beams, common.angle_min_rad, common.angle_increment_rad, rmin0, rmax0, max(beyond, rmax0)
    )
    stamps = np.array([r[0] for r in scans])
    laser_frame = first[7].lstrip("/")
    T_base_laser, base = _extrinsic(s.tf_static, laser_frame, base_frame, report)
    odom = _odometry_at(path, s, stamps + float(scan_time_offset_s), base, odom_frame, report, repair_reversing)
    scan_defects(report, stamps, odom, max_speed_mps=max_speed_mps, max_step_m=max_step_m)
    warn_defects(path, report)
    truth = None
    if s.truth:  # the simulator's bags (write_bag) carry the truth at the scans' stamps
        t = np.array(s.truth)
        at = match_stamps(stamps, t[:, 0], 1e-4)
        truth = np.full((len(stamps), 3), np.nan)
        truth[at[at >= 0]] = t[at >= 0, 1:]
    return LaserLog(stamps, ranges, odom, info, T_base_laser, truth, str(path), report)


def _extrinsic(tf_static, laser_frame, base_frame, report):
    for parent, child, x, y, yaw in tf_static:
        if child == laser_frame and (base_frame is None or parent == base_frame):
            return np.array([x, y, yaw]), parent
    report.add("no_laser_extrinsic", 1, f"no /tf_static transform to {laser_frame!r}: identity assumed")
    return np.zeros(3), base_frame or "base_link"


def _odometry_at(path, s: _Streams, stamps, base, odom_frame, report, repair: bool = False):
    if s.odom:
        od = np.array([r for r in s.odom])
        rec = _recording_order(od[:, 0], od[:, 1])
        report.add(
            "odom_stamps_backwards",
            count_stamps_backwards(od[rec, 0]),
            "odometry stamped earlier than the message recorded before it",
        )
        od = od[np.argsort(od[:, 0], kind="stable")]
        report.add(
            "odometry_contradicts_velocity",
            count_velocity_contradictions(od[:, 2:5], od[:, 5]),
            "odometry steps moving against the message's own forward velocity",
        )
        src_t, src_p = od[:, 0], od[:, 2:5]
        if repair:
            src_p, n, metres = repair_reversing(src_p, od[:, 5])
            report.add("odometry_steps_reversed", n, f"odometry steps driven backwards by the repair ({metres:.1f} m)")
    else:
        rows = [r for r in s.tf if r[2] == base and (odom_frame is None or r[1] == odom_frame)]
        if not rows:
            raise LogFormatError(path, None, f"no nav_msgs/Odometry topic and no /tf transform to {base!r}")
        tf = np.array([(r[0], r[3], r[4], r[5]) for r in rows])
        tf = tf[np.argsort(tf[:, 0], kind="stable")]
        src_t, src_p = tf[:, 0], tf[:, 1:4]
    outside = int(np.sum((stamps < src_t[0]) | (stamps > src_t[-1])))
    report.add("scans_outside_odometry", outside, "scans before the first or after the last odometry; clamped")
    src_t, first = np.unique(src_t, return_index=True)
    return interpolate_poses(src_t, src_p[first], stamps)


class Messages:
    """ROS messages of one typestore (ROS 1 Noetic or ROS 2 Humble), built from our arrays: the writers' part
    that knows message layouts (write_bag, io.mcap_run)."""

    def __init__(self, version: int):
        from rosbags.typesys import Stores, get_typestore

        self.version = version
        self.ts = ts = get_typestore(Stores.ROS1_NOETIC if version == 1 else Stores.ROS2_HUMBLE)
        if TF not in ts.types:  # rosbags' noetic store lacks tf2_msgs: declare it from its .msg text
            from rosbags.typesys import get_types_from_msg

            ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", TF))
        self.T = ts.types
        self.serialize = ts.serialize_ros1 if version == 1 else ts.serialize_cdr

    def header(self, stamp, frame, seq=0):
        ns = int(round(stamp * 1e9))
        t = self.T["builtin_interfaces/msg/Time"](sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
        H = self.T["std_msgs/msg/Header"]
        return H(seq=seq, stamp=t, frame_id=frame) if self.version == 1 else H(stamp=t, frame_id=frame)

    def quat(self, yaw):
        return self.T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=float(np.sin(yaw / 2)), w=float(np.cos(yaw / 2)))

    def vec3(self, x=0.0, y=0.0):
        return self.T["geometry_msgs/msg/Vector3"](x=float(x), y=float(y), z=0.0)

    def pose(self, p):
        T = self.T
        return T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](x=float(p[0]), y=float(p[1]), z=0.0), orientation=self.quat(p[2])
        )

    def tf(self, stamp, parent, child, pose, seq=0):
        T = self.T
        tr = T["geometry_msgs/msg/Transform"](translation=self.vec3(pose[0], pose[1]), rotation=self.quat(pose[2]))
        return T[TF](
            transforms=[
                T["geometry_msgs/msg/TransformStamped"](
                    header=self.header(stamp, parent, seq), child_frame_id=child, transform=tr
                )
            ]
        )

    def odom(self, stamp, pose, v, odom_frame, base_frame, seq=0):
        T, cov = self.T, np.zeros(36)
        tw = T["geometry_msgs/msg/TwistWithCovariance"](
            twist=T["geometry_msgs/msg/Twist"](linear=self.vec3(v), angular=self.vec3()), covariance=cov
        )
        return T[ODOM](
            header=self.header(stamp, odom_frame, seq),
            child_frame_id=base_frame,
            pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=self.pose(pose), covariance=cov),
            twist=tw,
        )

    def scan(self, stamp, info, ranges, laser_frame, seq=0):
        return self.T[SCAN](
            header=self.header(stamp, laser_frame, seq),
            angle_min=info.angle_min_rad,
            angle_max=info.angle_min_rad + info.fov_rad,
            angle_increment=info.angle_increment_rad,
            time_increment=0.0,
            scan_time=0.0,
            range_min=info.range_min_m,
            range_max=info.range_max_m,
            ranges=np.where(np.isfinite(ranges), ranges, np.inf).astype(np.float32),
            intensities=np.zeros(0, np.float32),
        )


def latched_qos():
    """ROS 2's QoS of a latched topic (/tf_static, /map): transient local, reliable, keep last 1."""
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

    never = QosTime(sec=0, nsec=0)
    return [
        Qos(
            history=QosHistory.KEEP_LAST,
            depth=1,
            reliability=QosReliability.RELIABLE,
            durability=QosDurability.TRANSIENT_LOCAL,
            deadline=never,
            lifespan=never,
            liveliness=QosLiveliness.AUTOMATIC,
            liveliness_lease_duration=never,
            avoid_ros_namespace_conventions=False,
        )
    ]


def bag_writer(path: Path, version: int, storage: str = "sqlite3"):
    """(a writer of a ROS 1 bag or ROS 2 bag folder into a hidden partial place beside ``path``, the function
    that moves the finished bag to ``path``, the one that removes the partial on failure). A ROS 2 bag's storage
    file is named after the bag (``<name>/<name>.db3`` or ``.mcap``), as ros2 bag record names it."""
    if storage not in ("sqlite3", "mcap"):
        raise ValueError(f"bag storage {storage!r}: choose sqlite3 or mcap")
    if version == 1 and storage != "sqlite3":
        raise ValueError("a ROS 1 bag has one storage format; storage=mcap needs version=2")
    partial = path.with_name(f".{path.name}.partial")
    shutil.rmtree(partial, ignore_errors=True) if partial.is_dir() else partial.unlink(missing_ok=True)
    if version == 1:
        from rosbags.rosbag1 import Writer

        tmp, writer = partial, Writer(partial)
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer

        partial.mkdir(parents=True)
        tmp = partial / path.name  # the bag folder under its own name: its storage file takes that name
        writer = Writer(
            tmp,
            version=9 if storage == "mcap" else 8,
            storage_plugin=StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3,
        )

    def finish() -> Path:
        if path.is_dir():
            shutil.rmtree(path)
        tmp.replace(path)  # written completely, then renamed: never half a bag under the final name
        if partial != tmp:
            partial.rmdir()
        return path

    def discard() -> None:
        shutil.rmtree(partial, ignore_errors=True) if partial.is_dir() else partial.unlink(missing_ok=True)

    return writer, finish, discard


def add_connection(writer, msgs: Messages, topic: str, msgtype: str, latched: bool = False):
    """A topic of ``msgtype``; ``latched``: a ROS 1 latching connection, a ROS 2 transient-local QoS."""
    if msgs.version == 1:
        return writer.add_connection(topic, msgtype, typestore=msgs.ts, latching=1 if latched else None)
    return writer.add_connection(
        topic, msgtype, typestore=msgs.ts, offered_qos_profiles=latched_qos() if latched else ()
    )


def write_bag(
    log: LaserLog,
    path,
    *,
    version: int = 1,
    storage: str = "sqlite3",
    scan_topic="/scan",
    odom_topic="/odom",
    odom_frame="odom",
    base_frame="base_link",
    laser_frame="laser",
    images: "CameraFrames | None" = None,
    rgb_topic="/camera/rgb",
    depth_topic="/camera/depth",
    camera_frame="camera",
) -> Path:
    """Write a LaserLog as a ROS1 bag (``version=1``) or ROS2 bag folder (``version=2``; ``storage`` sqlite3 or
    mcap).

    No-return beams are written as +inf (REP 117); odometry as nav_msgs/Odometry and /tf; the extrinsic
    on /tf_static, latched (ROS 1) / transient local (ROS 2) as robot_state_publisher offers it, so a player
    hands it to late subscribers. ``images``: camera frames as sensor_msgs/Image, rgb8 on ``rgb_topic`` and depth
    (16UC1 in millimetres or 32FC1 in metres) on ``depth_topic``. Reading the result back with :func:`read_bag`
    (and :func:`read_bag_images`) gives the same log (and frames).
    """
    path = Path(path)
    msgs = Messages(version)
    dt = np.diff(log.stamps, prepend=log.stamps[0] - 1.0)
    step = np.diff(log.odom[:, :2], axis=0, prepend=log.odom[:1, :2])
    v = (step[:, 0] * np.cos(log.odom[:, 2]) + step[:, 1] * np.sin(log.odom[:, 2])) / np.maximum(dt, 1e-6)
    writer, finish, discard = bag_writer(path, version, storage)
    try:
        _write_all(
            writer,
            msgs,
            log,
            v,
            scan_topic,
            odom_topic,
            odom_frame,
            base_frame,
            laser_frame,
            images,
            rgb_topic,
            depth_topic,
            camera_frame,
        )
    except BaseException:
        discard()
        raise
    return finish()


def _write_all(
    writer,
    msgs,
    log,
    v,
    scan_topic,
    odom_topic,
    odom_frame,
    base_frame,
    laser_frame,
    images=None,
    rgb_topic=None,
    depth_topic=None,
    camera_frame=None,
):
    T, ser = msgs.T, msgs.serialize
    with writer:
        if images is not None:
            c_rgb, c_depth = (
                add_connection(writer, msgs, rgb_topic, IMAGE),
                add_connection(writer, msgs, depth_topic, IMAGE),
            )
            for i, stamp in enumerate(images.stamps):
                ns = int(round(stamp * 1e9))
                for c, img, enc in ((c_rgb, images.rgb[i], "rgb8"), (c_depth, images.depth[i], images.depth_encoding)):
                    data, step = _encode(img, enc)
                    msg = T[IMAGE](
                        header=msgs.header(stamp, camera_frame, i),
                        height=img.shape[0],
                        width=img.shape[1],
                        encoding=enc,
                        is_bigendian=0,
                        step=step,
                        data=data,
                    )
                    writer.write(c, ns, ser(msg, IMAGE))

        c_static = add_connection(writer, msgs, "/tf_static", TF, latched=True)
        c_scan, c_odom = add_connection(writer, msgs, scan_topic, SCAN), add_connection(writer, msgs, odom_topic, ODOM)
        c_tf = add_connection(writer, msgs, "/tf", TF)
        c_truth = add_connection(writer, msgs, GROUND_TRUTH_TOPIC, ODOM) if log.ground_truth is not None else None
        t0 = float(log.stamps.min())
        writer.write(c_static, int(round(t0 * 1e9)), ser(msgs.tf(t0, base_frame, laser_frame, log.T_base_laser), TF))
        for i, stamp in enumerate(log.stamps):
            ns = int(round(stamp * 1e9))
            writer.write(c_scan, ns, ser(msgs.scan(stamp, log.info, log.ranges_m[i], laser_frame, i), SCAN))
            writer.write(c_odom, ns, ser(msgs.odom(stamp, log.odom[i], v[i], odom_frame, base_frame, i), ODOM))
            writer.write(c_tf, ns, ser(msgs.tf(stamp, odom_frame, base_frame, log.odom[i], i), TF))
            if c_truth is not None and np.all(np.isfinite(log.ground_truth[i])):
                writer.write(c_truth, ns, ser(msgs.odom(stamp, log.ground_truth[i], 0.0, "world", base_frame, i), ODOM))


def read_bag_extrinsic(path, laser_frame: str = "laser", base_frame: str | None = None) -> np.ndarray:
    """T_base_laser from a bag's /tf_static alone (for CARMEN logs, which carry no extrinsic)."""
    from rosbags.highlevel import AnyReader

    path = Path(path)
    try:
        with AnyReader([path]) as reader:
            conns = [c for c in reader.connections if c.topic == "/tf_static"]
            s = _Streams([], [], [], [], path, _Quaternions())
            for k, (conn, _, raw) in enumerate(reader.messages(connections=conns)):
                _collect(s, conn, reader.deserialize(raw, conn.msgtype), None, None, k)
    except Exception as e:
        raise LogFormatError(path, None, f"cannot read /tf_static: {e}") from e
    report = DefectReport()
    T, _ = _extrinsic(s.tf_static, laser_frame, base_frame, report)
    if report:
        raise LogFormatError(path, None, f"no /tf_static transform {base_frame or '<base>'} -> {laser_frame}")
    return T
