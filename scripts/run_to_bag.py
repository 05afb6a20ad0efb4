#!/usr/bin/env python3
"""Writes a stereotag run directory as a ROS 2 bag (MCAP), with the `rosbags` package: an
independent writer of the bags `stereotag import --bag` reads (its test fixtures), and a way to
feed a simulated run to ROS tools.

    python3 scripts/run_to_bag.py RUN_DIR OUT_BAG_DIR [--compressed] [--other-names]
        [--laser WORLD_YAML] [--pairs N] [--image-rate HZ] [--break WHAT]

What the bag holds (as a ROS 2 robot logs it):
- the stereo pairs as sensor_msgs/Image mono8 (or CompressedImage png with --compressed, the
  run's PNG files as they are), two CameraInfo (plumb_bob; the right one's projection carries the
  baseline), stamped alike;
- nav_msgs/Odometry moved to start at (0, 0, 0), as ROS odometry does (frame odom);
- the run's ground truth as an Odometry on /ground_truth (frame world);
- one sensor_msgs/Range topic a sonar (REP 117: +inf for no echo);
- /tf_static: base_link to each sensor's frame;
- with --laser, a LaserScan (181 beams over 180 degrees, 8 m) ray-cast in the world's walls at
  every ground-truth pose;
- with --other-names, other topic names, the odometry's child frame base_footprint (0.1 m below
  base_link) and both camera frames in tf.
The chunks' CRCs are filled in (rosbags leaves them 0, "not computed"; rosbag2 writes them).
--break makes a broken bag for the bad-input tests: encoding (bayer images), right-size (right
images half size), no-tf (no transform for sonar 2), info-size (CameraInfo larger than the
images).
"""
import argparse
import binascii
import csv
import math
import struct
from pathlib import Path

import numpy as np
import yaml
from PIL import Image as PilImage
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

BASE_NS = 1_700_000_000 * 10**9


TIME_SCALE = 1.0


def ns(t):
    return BASE_NS + round(float(t) * TIME_SCALE * 1e9)


def rows(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def quat(yaw=0.0, matrix=None):
    if matrix is None:
        return (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
    m = np.asarray(matrix, dtype=float)[:3, :3]
    w = math.sqrt(max(0.0, 1 + m[0, 0] + m[1, 1] + m[2, 2])) / 2
    x = math.sqrt(max(0.0, 1 + m[0, 0] - m[1, 1] - m[2, 2])) / 2
    y = math.sqrt(max(0.0, 1 - m[0, 0] + m[1, 1] - m[2, 2])) / 2
    z = math.sqrt(max(0.0, 1 - m[0, 0] - m[1, 1] + m[2, 2])) / 2
    x = math.copysign(x, m[2, 1] - m[1, 2])
    y = math.copysign(y, m[0, 2] - m[2, 0])
    z = math.copysign(z, m[1, 0] - m[0, 1])
    return (x, y, z, w)


def compose2(a, b):
    ax, ay, at = a
    bx, by, bt = b
    return (ax + math.cos(at) * bx - math.sin(at) * by, ay + math.sin(at) * bx + math.cos(at) * by, at + bt)


def inverse2(a):
    x, y, t = a
    return (-math.cos(t) * x - math.sin(t) * y, math.sin(t) * x - math.cos(t) * y, -t)


def walls_of(world_path):
    world = yaml.safe_load(open(world_path))
    segs = []
    for w in world.get("walls", []):
        pts = w["polyline_m"]
        pairs = list(zip(pts, pts[1:]))
        if w.get("closed"):
            pairs.append((pts[-1], pts[0]))
        segs.extend(pairs)
    return np.array([[a[0], a[1], b[0], b[1]] for a, b in segs], dtype=float)


def cast(segs, ox, oy, angles, max_range):
    """Range along each angle from (ox, oy) to the nearest wall, inf beyond max_range."""
    dx, dy = np.cos(angles)[:, None], np.sin(angles)[:, None]
    ax, ay, bx, by = (segs[:, i][None, :] for i in range(4))
    ex, ey = bx - ax, by - ay
    den = dx * ey - dy * ex
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((ax - ox) * ey - (ay - oy) * ex) / den
        u = ((ax - ox) * dy - (ay - oy) * dx) / den
    ok = (np.abs(den) > 1e-12) & (t > 0) & (u >= 0) & (u <= 1)
    t = np.where(ok, t, np.inf).min(axis=1)
    return np.where(t <= max_range, t, np.inf).astype(np.float32)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--compressed", action="store_true")
    ap.add_argument("--other-names", action="store_true")
    ap.add_argument("--laser", type=Path)
    ap.add_argument("--pairs", type=int)
    ap.add_argument("--image-rate", type=float, help="re-time the run so its pairs come at this rate (Hz), for speed figures")
    ap.add_argument("--break", dest="broken", choices=["encoding", "right-size", "no-tf", "info-size"])
    a = ap.parse_args()
    if a.image_rate:
        # Every time scaled so the pairs come at the rate asked (sonar and odometry with them).
        global TIME_SCALE
        pairs = rows(a.run / "stereo.csv")
        TIME_SCALE = (len(pairs) / a.image_rate) / float(pairs[-1]["t_s"])

    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    Time = T["builtin_interfaces/msg/Time"]
    Header = T["std_msgs/msg/Header"]

    def header(t_ns, frame):
        return Header(stamp=Time(sec=t_ns // 10**9, nanosec=t_ns % 10**9), frame_id=frame)

    def pose(x, y, z, q):
        return T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](x=x, y=y, z=z),
            orientation=T["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]),
        )

    def odometry(t_ns, frame, child, p):
        zero = np.zeros(36)
        return T["nav_msgs/msg/Odometry"](
            header=header(t_ns, frame),
            child_frame_id=child,
            pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose(p[0], p[1], 0.0, quat(p[2])), covariance=zero),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](
                twist=T["geometry_msgs/msg/Twist"](
                    linear=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                    angular=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                ),
                covariance=zero,
            ),
        )

    def transform(parent, child, xyz, q):
        return T["geometry_msgs/msg/TransformStamped"](
            header=header(BASE_NS, parent),
            child_frame_id=child,
            transform=T["geometry_msgs/msg/Transform"](
                translation=T["geometry_msgs/msg/Vector3"](x=xyz[0], y=xyz[1], z=xyz[2]),
                rotation=T["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]),
            ),
        )

    run = yaml.safe_load(open(a.run / "run.yaml"))
    rig = yaml.safe_load(open(a.run / run["robot"]["rig"]))
    layout = run["robot"]["sonar"]
    other = a.other_names
    names = {
        "left": "/cam_l/image_raw" if other else "/stereo/left/image_raw",
        "right": "/cam_r/image_raw" if other else "/stereo/right/image_raw",
        "odom": "/wheel/odometry" if other else "/odom",
        "sonar": "/range/s{}" if other else "/sonar/{}",
        "truth": "/mocap/robot" if other else "/ground_truth",
    }
    if a.compressed:
        names["left"] += "/compressed"
        names["right"] += "/compressed"
    info_topic = {s: names[s].removesuffix("/compressed").rsplit("/", 1)[0] + "/camera_info" for s in ("left", "right")}
    base = "base_link"
    odom_child = "base_footprint" if other else base
    frames = {"left": "left_camera_optical", "right": "right_camera_optical" if other else "left_camera_optical"}

    with Writer(a.out, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conn = {}

        def add(key, topic, msgtype):
            conn[key] = (w.add_connection(topic, msgtype, typestore=ts), msgtype)

        def write(key, t_ns, msg):
            c, msgtype = conn[key]
            w.write(c, t_ns, ts.serialize_cdr(msg, msgtype))

        img_type = "sensor_msgs/msg/CompressedImage" if a.compressed else "sensor_msgs/msg/Image"
        add("left", names["left"], img_type)
        add("right", names["right"], img_type)
        add("left_info", info_topic["left"], "sensor_msgs/msg/CameraInfo")
        add("right_info", info_topic["right"], "sensor_msgs/msg/CameraInfo")
        add("odom", names["odom"], "nav_msgs/msg/Odometry")
        add("truth", names["truth"], "nav_msgs/msg/Odometry")
        add("tf_static", "/tf_static", "tf2_msgs/msg/TFMessage")
        for k in range(len(layout["sensors"])):
            add(f"sonar{k}", names["sonar"].format(k), "sensor_msgs/msg/Range")
        if a.laser:
            add("scan", "/scan", "sensor_msgs/msg/LaserScan")

        # tf_static first.
        rfl = np.array(rig["stereotag"]["robot_from_left"], dtype=float)
        tfs = [transform(base, frames["left"], rfl[:3, 3], quat(matrix=rfl))]
        if other:
            t = np.array(rig["cam1"]["T_cn_cnm1"], dtype=float)
            rfr = rfl @ np.linalg.inv(t)
            tfs.append(transform(base, frames["right"], rfr[:3, 3], quat(matrix=rfr)))
            tfs.append(transform(odom_child, base, (0.0, 0.0, 0.1), quat(0.0)))
        for k, s in enumerate(layout["sensors"]):
            if a.broken == "no-tf" and k == 2:
                continue
            tfs.append(transform(base, f"sonar_{k}", (s["x_m"], s["y_m"], 0.2), quat(s["bearing_rad"])))
        if a.laser:
            tfs.append(transform(base, "laser", (0.1, 0.0, 0.25), quat(0.0)))
        write("tf_static", BASE_NS, T["tf2_msgs/msg/TFMessage"](transforms=tfs))

        events = []
        stereo = rows(a.run / "stereo.csv")
        if a.pairs is not None:
            stereo = stereo[: a.pairs]
        last_t = float(stereo[-1]["t_s"]) if (a.pairs is not None and stereo) else math.inf
        for i, e in enumerate(stereo):
            events.append((ns(e["t_s"]), 0, "pair", e))
        odo = [r for r in rows(a.run / "odometry.csv") if float(r["t_s"]) <= last_t + 1]
        truth = [r for r in rows(a.run / "ground_truth.csv") if float(r["t_s"]) <= last_t + 1]
        start = tuple(float(odo[0][k]) for k in ("x_m", "y_m", "theta_rad"))
        for r in odo:
            events.append((ns(r["t_s"]), 1, "odom", r))
        for r in truth:
            events.append((ns(r["t_s"]), 2, "truth", r))
        for r in rows(a.run / "sonar.csv"):
            if float(r["t_s"]) <= last_t + 1:
                events.append((ns(r["t_s"]), 3, "sonar", r))
        if a.laser:
            segs = walls_of(a.laser)
            for r in truth:
                events.append((ns(r["t_s"]), 4, "scan", r))
        events.sort(key=lambda e: (e[0], e[1]))

        cams = {}
        for side, key in (("left", "cam0"), ("right", "cam1")):
            c = rig[key]
            fx, fy, cx, cy = c["intrinsics"]
            width, height = c["resolution"]
            if a.broken == "info-size":
                width, height = width + 16, height
            t = np.array(rig["cam1"]["T_cn_cnm1"], dtype=float)
            assert np.allclose(t[:3, :3], np.eye(3)), "the fixture writes rigs whose cameras are parallel"
            tx = fx * t[0, 3] if side == "right" else 0.0
            d = list(c["distortion_coeffs"]) + [0.0]
            cams[side] = T["sensor_msgs/msg/CameraInfo"](
                header=header(BASE_NS, frames[side]),
                height=height,
                width=width,
                distortion_model="plumb_bob",
                d=np.array(d[:5], dtype=float),
                k=np.array([fx, 0, cx, 0, fy, cy, 0, 0, 1], dtype=float),
                r=np.eye(3).flatten(),
                p=np.array([fx, 0, cx, tx, 0, fy, cy, 0, 0, 0, 1, 0], dtype=float),
                binning_x=0,
                binning_y=0,
                roi=T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False),
            )

        infos_written = False
        for t_ns, _, kind, r in events:
            if kind == "pair":
                if not infos_written:
                    write("left_info", t_ns, cams["left"])
                    write("right_info", t_ns, cams["right"])
                    infos_written = True
                for side in ("left", "right"):
                    path = a.run / r[side]
                    frame = frames[side]
                    if a.compressed:
                        msg = T["sensor_msgs/msg/CompressedImage"](
                            header=header(t_ns, frame), format="mono8; png compressed mono8", data=np.frombuffer(path.read_bytes(), dtype=np.uint8)
                        )
                    else:
                        img = PilImage.open(path).convert("L")
                        if a.broken == "right-size" and side == "right":
                            img = img.resize((img.width // 2, img.height // 2))
                        pixels = np.asarray(img, dtype=np.uint8)
                        enc = "bayer_rggb8" if a.broken == "encoding" else "mono8"
                        msg = T["sensor_msgs/msg/Image"](
                            header=header(t_ns, frame), height=pixels.shape[0], width=pixels.shape[1], encoding=enc, is_bigendian=0, step=pixels.shape[1], data=pixels.flatten()
                        )
                    write(side, t_ns, msg)
            elif kind == "odom":
                p = compose2(inverse2(start), tuple(float(r[k]) for k in ("x_m", "y_m", "theta_rad")))
                write("odom", t_ns, odometry(t_ns, "odom", odom_child, p))
            elif kind == "truth":
                p = tuple(float(r[k]) for k in ("x_m", "y_m", "theta_rad"))
                write("truth", t_ns, odometry(t_ns, "world", base, p))
            elif kind == "sonar":
                k = int(r["sensor"])
                rng = float(r["range_m"]) if r["range_m"] else math.inf
                msg = T["sensor_msgs/msg/Range"](
                    header=header(t_ns, f"sonar_{k}"), radiation_type=0, field_of_view=float(layout["cone_rad"]), min_range=float(layout.get("min_range_m", 0.0)), max_range=float(layout["max_range_m"]), range=rng
                )
                write(f"sonar{k}", t_ns, msg)
            elif kind == "scan":
                x, y, th = (float(r[k]) for k in ("x_m", "y_m", "theta_rad"))
                lx, ly = x + 0.1 * math.cos(th), y + 0.1 * math.sin(th)
                angles = np.linspace(-math.pi / 2, math.pi / 2, 181)
                ranges = cast(segs, lx, ly, th + angles, 8.0)
                msg = T["sensor_msgs/msg/LaserScan"](
                    header=header(t_ns, "laser"), angle_min=-math.pi / 2, angle_max=math.pi / 2, angle_increment=math.pi / 180, time_increment=0.0, scan_time=0.1, range_min=0.05, range_max=8.0, ranges=ranges, intensities=np.zeros(0, dtype=np.float32)
                )
                write("scan", t_ns, msg)

    for f in a.out.glob("*.mcap"):
        add_chunk_crcs(f)


def add_chunk_crcs(path):
    """Fills in each uncompressed chunk's CRC of its records, as rosbag2's MCAP writer does."""
    b = bytearray(path.read_bytes())
    i = 8
    while i < len(b):
        op, n = b[i], struct.unpack_from("<Q", b, i + 1)[0]
        if op == 0x06:
            body = i + 9
            clen = struct.unpack_from("<I", b, body + 28)[0]
            compression = bytes(b[body + 32 : body + 32 + clen])
            rlen = struct.unpack_from("<Q", b, body + 32 + clen)[0]
            start = body + 32 + clen + 8
            if compression == b"":
                struct.pack_into("<I", b, body + 24, binascii.crc32(b[start : start + rlen]))
        if op == 0x0F:  # data end: the data section's CRC stays 0 (not computed)
            break
        i += 9 + n
    path.write_bytes(bytes(b))


if __name__ == "__main__":
    main()
