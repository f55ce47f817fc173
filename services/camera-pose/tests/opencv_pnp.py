#!/usr/bin/env python3
"""Reference PnP for tests/opencv_compare.rs: OpenCV SQPnP, then LM refinement.

Usage: opencv_pnp.py IN.json OUT.json

IN:  {"camera_matrix": [[fx,0,cx],[0,fy,cy],[0,0,1]],
      "object_points": [[x,y,z], ...],                  # parent body frame, m
      "samples": [{"image_points": [[u,v], ...]}, ...]}  # px, same order
OUT: {"results": [{"ok": bool, "rvec": [3], "tvec": [3]}, ...],
      "opencv_version": str, "mean_solve_us": float}
(rvec, tvec) map object points into the camera frame: X_c = R(rvec) X + tvec.
Exit code 2 with a message on stderr if OpenCV or NumPy is missing.
"""
import json
import sys
import time

try:
    import cv2
    import numpy as np
except ImportError as exc:  # the Rust test turns this into a clear failure
    sys.stderr.write(
        f"opencv_pnp.py: cannot import OpenCV/NumPy ({exc}); "
        "install them with `pip install -r tests/requirements.txt` "
        "(opencv-python-headless, numpy)\n"
    )
    sys.exit(2)


def main() -> int:
    if len(sys.argv) != 3:
        sys.stderr.write("usage: opencv_pnp.py IN.json OUT.json\n")
        return 1
    with open(sys.argv[1], encoding="utf-8") as f:
        data = json.load(f)
    k = np.array(data["camera_matrix"], dtype=np.float64)
    obj = np.array(data["object_points"], dtype=np.float64).reshape(-1, 1, 3)
    dist = np.zeros(5)
    results = []
    total = 0.0
    for s in data["samples"]:
        img = np.array(s["image_points"], dtype=np.float64).reshape(-1, 1, 2)
        t0 = time.perf_counter()
        ok, rvec, tvec = cv2.solvePnP(obj, img, k, dist, flags=cv2.SOLVEPNP_SQPNP)
        if ok:
            rvec, tvec = cv2.solvePnPRefineLM(obj, img, k, dist, rvec, tvec)
        total += time.perf_counter() - t0
        results.append(
            {
                "ok": bool(ok),
                "rvec": [float(v) for v in np.ravel(rvec)] if ok else [0.0, 0.0, 0.0],
                "tvec": [float(v) for v in np.ravel(tvec)] if ok else [0.0, 0.0, 0.0],
            }
        )
    out = {
        "results": results,
        "opencv_version": cv2.__version__,
        "mean_solve_us": 1e6 * total / max(1, len(results)),
    }
    with open(sys.argv[2], "w", encoding="utf-8") as f:
        json.dump(out, f)
    return 0


if __name__ == "__main__":
    sys.exit(main())
