"""`topside export`: the MCAP archive of a recording (.rrd written by `topside track --rrd`), read back through
rerun's API and fed to the same Archive that `track --mcap` feeds, so both archives hold the same messages.

What the .rrd keeps for this (viewer/recording.py): the rig and calibration files and the tracker's options
(`archive/inputs`), every estimate whole (`archive/estimates/<cone>`) with the filter's camera poses at its time
(`world/filter/cameras/<camera>`), and per frame the JPEG, the marker outlines and axes, the camera pose, the marker
count and the reprojection error.
"""

from __future__ import annotations

import tempfile
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pyarrow as pa
import rerun as rr
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

from tracking.camera import load_camera
from tracking.errors import InputError
from tracking.estimate import ConeEstimate
from tracking.rig import load_rig
from viewer.archive.frames import FrameView
from viewer.archive.writer import Archive, ArchiveInputs
from viewer.readback import chunks_by_entity
from viewer.recording import AXES, FILTER_CAMERAS, TIMELINE

Rows = dict[int, dict[str, object]]  # capture time ns -> component -> row value


def entity_rows(chunks: list[rr.chunk.Chunk], components: list[str], index: str | None = None) -> Rows:
    """The temporal rows of an entity by capture time (ns): the named components' values, and `index`'s value."""
    out: Rows = {}
    for chunk in chunks:
        rb = chunk.to_record_batch()
        names = rb.schema.names
        if TIMELINE not in names:
            continue  # static
        times = rb.column(names.index(TIMELINE)).cast(pa.int64()).to_numpy()
        cols = {c: rb.column(names.index(c)) for c in components if c in names}
        idx = rb.column(names.index(index)).to_pylist() if index and index in names else None
        for i, t in enumerate(times):
            row = out.setdefault(int(t), {})
            for c, col in cols.items():
                if col[i].is_valid:
                    row[c] = col[i]
            if idx is not None and idx[i] is not None:
                row[index] = idx[i]
    return out


def _blob(value: pa.Scalar) -> bytes:
    """The bytes of a one-blob row (EncodedImage or VideoStream sample)."""
    return value.values[0].values.to_numpy(zero_copy_only=False).astype(np.uint8).tobytes()


def _rgb(packed: int) -> tuple[int, int, int]:
    """0xRRGGBBAA to (r, g, b)."""
    return ((packed >> 24) & 0xFF, (packed >> 16) & 0xFF, (packed >> 8) & 0xFF)


def _strips(row: dict[str, object]) -> list[np.ndarray]:
    return [np.array(s, dtype=np.float64) for s in row["LineStrips2D:strips"].as_py()]


def frame_views(chunks: dict[str, list[rr.chunk.Chunk]], camera: str) -> list[FrameView]:
    """Every frame of one camera as the recording stores it."""
    base = f"/world/cameras/{camera}"
    images = entity_rows(chunks.get(f"{base}/image", []), ["EncodedImage:blob", "VideoStream:sample"],
                         f"frame_{camera}")
    overlays = entity_rows(chunks.get(f"{base}/image/markers", []),
                           ["LineStrips2D:strips", "LineStrips2D:labels", "LineStrips2D:colors"])
    poses = pose_rows(chunks.get(base, []))
    counts = entity_rows(chunks.get(f"/health/{camera}/markers", []), ["Scalars:scalars"])
    reproj = entity_rows(chunks.get(f"/health/{camera}/reprojection_error_px", []), ["Scalars:scalars"])
    views = []
    for ns, row in sorted(images.items()):
        if "VideoStream:sample" in row:
            image, fmt = _blob(row["VideoStream:sample"]), "h264"
        elif "EncodedImage:blob" in row:
            image, fmt = _blob(row["EncodedImage:blob"]), "jpeg"
        else:
            continue
        m = overlays.get(ns, {})
        outlines, segments = [], []
        if "LineStrips2D:strips" in m:  # outlines are labelled with their marker id, reprojected axes are not
            labels = m["LineStrips2D:labels"].as_py() if "LineStrips2D:labels" in m else []
            colors = m["LineStrips2D:colors"].as_py() if "LineStrips2D:colors" in m else []
            for strip, label, c in zip(_strips(m), labels, colors, strict=True):
                if label:
                    outlines.append((int(label), strip[:4], _rgb(c)))
                else:
                    segments.append((strip, _rgb(c)))
        T = poses.get(ns)
        n = counts.get(ns, {}).get("Scalars:scalars")
        r = reproj.get(ns, {}).get("Scalars:scalars")
        views.append(FrameView(camera, ns, int(row.get(f"frame_{camera}", len(views))), image,
                               outlines, segments, T, int(n.as_py()[0]) if n is not None else 0,
                               float(r.as_py()[0]) if r is not None else float("nan"), fmt))
    return views


def pose_rows(chunks: list[rr.chunk.Chunk]) -> dict[int, np.ndarray]:
    """An entity's transforms (4, 4) by capture time (ns), where it has both translation and matrix."""
    out = {}
    for ns, row in entity_rows(chunks, ["Transform3D:translation", "Transform3D:mat3x3"]).items():
        if "Transform3D:translation" in row and "Transform3D:mat3x3" in row:
            T = np.eye(4)
            # rerun stores mat3x3 column-major
            T[:3, :3] = np.array(row["Transform3D:mat3x3"].as_py()[0], dtype=np.float64).reshape(3, 3).T
            T[:3, 3] = np.array(row["Transform3D:translation"].as_py()[0], dtype=np.float64)
            out[ns] = T
    return out


def filter_cameras(chunks: dict[str, list[rr.chunk.Chunk]]) -> dict[int, dict[str, np.ndarray]]:
    """Where the fused filter had each camera, by capture time (ns): camera -> T_jacket_camera (4, 4)."""
    prefix = f"/{FILTER_CAMERAS}/"
    out: dict[int, dict[str, np.ndarray]] = {}
    for path, entity_chunks in sorted(chunks.items()):
        if path.startswith(prefix):
            for ns, T in pose_rows(entity_chunks).items():
                out.setdefault(ns, {})[path[len(prefix):]] = T
    return out


def estimates(chunks: dict[str, list[rr.chunk.Chunk]]) -> list[tuple[int, ConeEstimate]]:
    """Every estimate the recording stores whole, with its capture time in ns and the filter's cameras then."""
    cameras = filter_cameras(chunks)
    out = []
    prefix = "/archive/estimates/"
    for path, entity_chunks in chunks.items():
        if not path.startswith(prefix):
            continue
        cone = path[len(prefix):]
        comps = ["offset", "covariance", "cameras", "withheld"]  # withheld: absent from older recordings
        keys = {c: next((k for k in entity_chunks[0].to_record_batch().schema.names if k.endswith(c)), c)
                for c in comps}
        rows = entity_rows(entity_chunks, list(keys.values()))
        for ns, row in sorted(rows.items()):
            cov = np.array(row[keys["covariance"]].as_py(), dtype=np.float64) if keys["covariance"] in row else None
            names = row[keys["cameras"]].as_py()[0] if keys["cameras"] in row else ""
            withheld = row[keys["withheld"]].as_py()[0] if keys["withheld"] in row else ""
            out.append((ns, ConeEstimate(ns / 1e9, cone, np.array(row[keys["offset"]].as_py(), dtype=np.float64),
                                         tuple(names.split()) if names else (),
                                         cov.reshape(3, 3) if cov is not None and cov.size == 9 else None,
                                         cameras.get(ns), withheld)))
    return out


def truth(chunks: dict[str, list[rr.chunk.Chunk]]) -> list[tuple[int, str, np.ndarray]]:
    """The truth rows the recording holds, (ns, cone, (3,) offset)."""
    by_cone: dict[str, dict[int, np.ndarray]] = {}
    for path, entity_chunks in chunks.items():
        parts = path.strip("/").split("/")
        if len(parts) != 4 or parts[0] != "offsets" or parts[3] != "truth":
            continue
        axis, cone = AXES.index(parts[1]), parts[2]
        for ns, row in entity_rows(entity_chunks, ["Scalars:scalars"]).items():
            if "Scalars:scalars" in row:
                values = by_cone.setdefault(cone, {}).setdefault(ns, np.full(3, np.nan))
                values[axis] = row["Scalars:scalars"].as_py()[0]
    return [(ns, cone, v) for cone, rows in by_cone.items() for ns, v in rows.items()]


def export_recording(rrd: Path, out: Path, info: Mapping[str, str] | None = None,
                     key: Ed25519PrivateKey | None = None, offsets_csv: bytes | None = None, video: str = "jpeg"
                     ) -> int:
    """Write the archive of a recording; returns the number of messages."""
    rrd = Path(rrd)
    if not rrd.is_file():
        raise InputError(rrd, "recording not found")
    try:
        chunks = chunks_by_entity(rrd)
    except Exception as exc:
        raise InputError(rrd, f"cannot be read as a Rerun recording ({exc})") from None
    doc = entity_rows_static(chunks.get("/archive/inputs", []), "TextDocument:text")
    if doc is None:
        raise InputError(rrd, "holds no rig and calibration files (expected a recording written by `topside track "
                              "--rrd` of this version)", "archive/inputs")
    inputs = ArchiveInputs.from_json(doc)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        (folder / inputs.rig_name).write_bytes(inputs.rig_text)
        cal_paths = {}
        for name, data in inputs.calibrations.items():
            path = folder / "calibration_files" / Path(name).name if Path(name).is_absolute() else folder / name
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(data)
            cal_paths[name] = path
        rig = load_rig(folder / inputs.rig_name)
        cameras = {c.name: load_camera(cal_paths[c.calibration]) for c in rig.cameras}
    events: list[tuple[int, int, int, object]] = []
    for cam in rig.cameras:
        events += [(v.ns, 0, i, v) for i, v in enumerate(frame_views(chunks, cam.name))]
    events += [(ns, 1, i, e) for i, (ns, e) in enumerate(estimates(chunks))]
    events.sort(key=lambda e: e[:3])
    archive = Archive(out, rig, inputs, cameras, info, truth(chunks), key, video=video)
    for ns, kind, _, item in events:
        if kind == 0:
            archive.frame(item)
        else:
            archive.estimate(item, ns)
    manifest = archive.close(offsets_csv)
    return sum(c["messages"] for c in manifest["channels"].values())


def entity_rows_static(chunks: list[rr.chunk.Chunk], component: str) -> str | None:
    """The first value of a static one-string component."""
    for chunk in chunks:
        rb = chunk.to_record_batch()
        if component in rb.schema.names:
            values = rb.column(rb.schema.names.index(component)).to_pylist()
            if values and values[0]:
                return values[0][0]
    return None
