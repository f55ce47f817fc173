#!/usr/bin/env python3
"""Check camera-pose against OpenCV on the frames a run recorded.

Reads a shoal recording with the official MCAP readers (no shoal code): the
follower's camera frames (`sensor_msgs/msg/Image`), what camera-pose made of
each (`beacons`: the centroids it identified; `leader_pose`: its PnP), and
the camera, beacon layout and detector settings from the recording's
`shoal.run` metadata. For every frame camera-pose solved, OpenCV does the
same job its own way: a threshold over the frame's background,
`connectedComponentsWithStats`, intensity-weighted centroids, and
`solvePnP` on the centroids matched to camera-pose's identities. Prints a
JSON report; exits non-zero if a centroid or a pose disagrees, or if too few
frames were checked.

usage: check_vision.py RECORDING VEHICLE
"""
import json
import math
import sys
import tomllib

import cv2
import numpy as np
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

CENTROID_TOL_PX = 0.5
# Position agreement: 2 cm plus 1 % of the range (two solvers, the same data).
POSE_TOL_M = 0.02
POSE_TOL_FRACTION = 0.01


def settings(reader):
    for m in reader.iter_metadata():
        if m.name == "shoal.run":
            eff = tomllib.loads(m.metadata["effective_toml"])
            return eff["camera"], eff["beacons"], eff["detect"]
    raise SystemExit("no shoal.run metadata with effective_toml")


def blobs(img, detect):
    """Intensity-weighted centroids of the bright components, OpenCV's way."""
    bg = float(np.median(img))
    sigma = max(bg - float(np.percentile(img, 15.87)), 0.5)
    height = max(detect["threshold_sigma"] * sigma, detect["min_contrast_dn"])
    low = bg + detect["grow_fraction"] * height
    _, mask = cv2.threshold(img, low, 255, cv2.THRESH_BINARY)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    out = []
    w = np.clip(img.astype(np.float64) - bg, 0.0, None)
    for k in range(1, n):
        if stats[k, cv2.CC_STAT_AREA] < detect["min_area_px"]:
            continue
        ys, xs = np.nonzero(labels == k)
        if img[ys, xs].max() <= bg + height:
            continue  # no seed pixel: not a blob by the same rule
        ww = w[ys, xs]
        s = ww.sum()
        out.append(((xs * ww).sum() / s + 0.5, (ys * ww).sum() / s + 0.5))
    return out


def main(path, vehicle):
    frames, beacons, poses = {}, {}, {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        camera, layout, detect = settings(reader)
        f.seek(0)
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        topics = [f"/{vehicle}/image", f"/{vehicle}/beacons", f"/{vehicle}/leader_pose"]
        for schema, channel, msg, dec in reader.iter_decoded_messages(topics=topics):
            if channel.topic.endswith("/image"):
                if schema.name != "sensor_msgs/msg/Image" or dec.encoding != "mono8":
                    raise SystemExit(f"{channel.topic}: {schema.name} {dec.encoding}")
                t = dec.header.stamp.sec * 1_000_000_000 + dec.header.stamp.nanosec
                img = np.frombuffer(bytes(dec.data), dtype=np.uint8).reshape(dec.height, dec.step)
                frames[t] = img[:, : dec.width]
            elif channel.topic.endswith("/beacons"):
                beacons[dec.header.origin_sim_time_ns] = dec
            else:
                poses[dec.header.origin_sim_time_ns] = dec

    width, height = camera["width_px"], camera["height_px"]
    f_px = 0.5 * width / math.tan(math.radians(camera["fov_deg"]) / 2)
    k_mat = np.array([[f_px, 0, width / 2], [0, f_px, height / 2], [0, 0, 1]], dtype=np.float64)
    if any(camera["mount_rpy_deg"]):
        raise SystemExit("this check assumes a camera looking along body x")
    mount = np.array(camera["mount_position_body_m"])
    points = np.array(layout["positions_body_m"], dtype=np.float64)

    checked, worst_px, pose_diffs = 0, 0.0, []
    for t, img in sorted(frames.items()):
        b, p = beacons.get(t), poses.get(t)
        if b is None or p is None or b.identification != 0 or not p.valid:
            continue
        found = blobs(img, detect)
        if not found:
            raise SystemExit(f"t={t}: camera-pose solved a frame in which OpenCV finds nothing")
        obj, pix = [], []
        for k in range(b.count):
            if not b.visible[k]:
                continue
            u, v = b.pixels_uv[2 * k], b.pixels_uv[2 * k + 1]
            d, c = min((math.hypot(cx - u, cy - v), (cx, cy)) for cx, cy in found)
            worst_px = max(worst_px, d)
            if d > CENTROID_TOL_PX:
                raise SystemExit(f"t={t}: beacon {k} at ({u:.2f}, {v:.2f}); OpenCV's nearest blob is {d:.2f} px away")
            obj.append(points[k])
            pix.append(c)
        ok, rvec, tvec = cv2.solvePnP(
            np.array(obj), np.array(pix), k_mat, None, flags=cv2.SOLVEPNP_SQPNP
        )
        ok, rvec, tvec = cv2.solvePnP(
            np.array(obj), np.array(pix), k_mat, None, rvec, tvec, True, cv2.SOLVEPNP_ITERATIVE
        )
        if not ok:
            raise SystemExit(f"t={t}: OpenCV's solvePnP failed where camera-pose solved")
        tx, ty, tz = tvec.ravel()
        # Optical (x right, y down, z forward) -> body (x forward, y starboard, z down).
        body = np.array([tz, tx, ty]) + mount
        ours = np.array(p.parent_position_body_m)
        diff = float(np.linalg.norm(body - ours))
        tol = POSE_TOL_M + POSE_TOL_FRACTION * float(np.linalg.norm(ours))
        if diff > tol:
            raise SystemExit(f"t={t}: OpenCV puts the parent at {body}, camera-pose at {ours} ({diff:.3f} m apart)")
        pose_diffs.append(diff)
        checked += 1

    if checked < 0.8 * len(frames) or checked == 0:
        raise SystemExit(f"only {checked} of {len(frames)} frames had a fix to check")
    pose_diffs.sort()
    print(json.dumps({
        "vehicle": vehicle,
        "frames": len(frames),
        "checked": checked,
        "centroid_max_px": round(worst_px, 4),
        "pose_diff_p50_m": round(pose_diffs[len(pose_diffs) // 2], 5),
        "pose_diff_max_m": round(pose_diffs[-1], 5),
    }))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
