"""The paper's estimators: its 10-sample running average per channel (eq. 17–21), and every pair offset raw."""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable, Iterator

import numpy as np

from tracking.estimate import ConeEstimate
from tracking.offsets import PairOffset
from tracking.rig import Rig

PAPER_WINDOW = 10  # samples (eq. 17–20)
def paper_roles(rig: Rig) -> dict[tuple[str, str], str]:
    """(cone, face) -> "x" or "y": the face whose outward normal runs closer to jacket y (so that its plane holds jacket
    x) is the paper's camera 1. By the normal, not the marker's x axis: a marker may be mounted turned about it."""
    roles: dict[tuple[str, str], str] = {}
    by_id = rig.marker_by_id
    faces_by_cone: dict[str, list[tuple[str, np.ndarray]]] = {}
    for pair in rig.all_pairs():
        normal = by_id[pair.jacket].T_body_marker[:3, 2]
        faces_by_cone.setdefault(pair.cone, []).append((pair.face, normal))
    for cone, faces in faces_by_cone.items():
        ordered = sorted(faces, key=lambda f: -abs(f[1][1]) + abs(f[1][0]))  # most y-like normal first, stable
        for rank, (face, normal) in enumerate(ordered):
            if len(ordered) == 1:
                roles[(cone, face)] = "x" if abs(normal[1]) >= abs(normal[0]) else "y"
            else:
                roles[(cone, face)] = "x" if rank == 0 else "y"
    return roles


class PaperAverager:
    """The paper's filter for one cone: camera 1 gives dx and dz1, camera 2 gives dy and dz2, each averaged."""

    def __init__(self, cone: str, window: int = PAPER_WINDOW) -> None:
        self.cone = cone
        self.channels: dict[str, deque[tuple[float, str]]] = {k: deque(maxlen=window) for k in ("x", "y", "z1", "z2")}

    def update(self, m: PairOffset, role: str) -> ConeEstimate:
        """Add one camera's pair offset and return the averaged estimate at its capture time."""
        if role == "x":
            self.channels["x"].append((float(m.offset[0]), m.camera))
            self.channels["z1"].append((float(m.offset[2]), m.camera))
        else:
            self.channels["y"].append((float(m.offset[1]), m.camera))
            self.channels["z2"].append((float(m.offset[2]), m.camera))
        mean = {k: (float(np.mean([v for v, _ in ch])) if ch else np.nan) for k, ch in self.channels.items()}
        zs = [mean[k] for k in ("z1", "z2") if not np.isnan(mean[k])]
        dz = float(np.mean(zs)) if zs else np.nan  # eq. 21
        cameras = tuple(sorted({c for ch in self.channels.values() for _, c in ch}))
        return ConeEstimate(m.time, self.cone, np.array([mean["x"], mean["y"], dz]), cameras)


def paper_filter(rig: Rig, measurements: Iterable[PairOffset]) -> Iterator[ConeEstimate]:
    """The paper's mode over time-ordered measurements: one estimate per measurement, per cone."""
    roles = paper_roles(rig)
    averagers: dict[str, PaperAverager] = {}
    for m in measurements:
        avg = averagers.setdefault(m.cone, PaperAverager(m.cone))
        yield avg.update(m, roles[(m.cone, m.face)])


def raw_estimates(measurements: Iterable[PairOffset]) -> Iterator[ConeEstimate]:
    """Every camera's pair offset as it is, unfiltered."""
    for m in measurements:
        yield ConeEstimate(m.time, m.cone, m.offset.copy(), (m.camera,), m.covariance)
