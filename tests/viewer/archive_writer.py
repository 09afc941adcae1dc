"""A writer for the truncation and SIGKILL tests: synthetic frames and estimates into an archive, in real time.

Run as `python -m tests.viewer.archive_writer RIG OUT SECONDS [--forever] [--key PRIVATE.pem] [--stopped WHY]`:
SECONDS of capture time at 15 FPS per camera (a chunk per second), then close (as a run that ended early, WHY, with
--stopped); with --forever it never closes (the test kills it) and prints one line per chunk written.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import cv2
import numpy as np

from tracking.camera import load_camera
from tracking.estimate import ConeEstimate
from tracking.rig import load_rig
from viewer.archive import Archive, ArchiveInputs, FrameView
from viewer.archive.manifest import load_private_key

FPS = 15
T0_NS = 100 * 10**9
IMAGE_SIZE = (160, 120)


def main(rig_path: Path, out: Path, seconds: float, forever: bool, key: Path | None, stopped: str = "") -> None:
    rig = load_rig(rig_path)
    cameras = {c.name: load_camera(rig.resolve(c.calibration)) for c in rig.cameras}
    archive = Archive(out, rig, ArchiveInputs.from_rig(rig, {"mode": "synthetic"}), cameras,
                      key=load_private_key(key) if key else None)
    rng = np.random.default_rng(0)
    k = 0
    while forever or k < seconds * FPS:
        ns = T0_NS + k * 10**9 // FPS
        for i, cam in enumerate(cameras):
            noise = rng.integers(0, 255, (IMAGE_SIZE[1], IMAGE_SIZE[0]), dtype=np.uint8)
            jpeg = cv2.imencode(".jpg", noise)[1].tobytes()
            corners = np.array([[10, 10], [50, 10], [50, 50], [10, 50]], dtype=np.float64) + k % 7
            archive.frame(FrameView(cam, ns + i, k, jpeg, [(1, corners, (0, 255, 0))], [], None, 1, 0.1))
        archive.estimate(ConeEstimate(0.0, "A", np.array([0.01, 0.02, 0.3 - k * 1e-3]), tuple(cameras),
                                      np.eye(3) * 1e-4), ns + len(cameras))
        if forever and k % FPS == 0:
            print(f"second {k // FPS}", flush=True)
            time.sleep(0.01)
        k += 1
    archive.close(stopped=stopped)


if __name__ == "__main__":
    key_arg = sys.argv[sys.argv.index("--key") + 1] if "--key" in sys.argv else None
    why = sys.argv[sys.argv.index("--stopped") + 1] if "--stopped" in sys.argv else ""
    main(Path(sys.argv[1]), Path(sys.argv[2]), float(sys.argv[3]), "--forever" in sys.argv,
         Path(key_arg) if key_arg else None, why)
