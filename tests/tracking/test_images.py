"""Reading videos into frames: the H.264 packet of every frame, whatever the decoder's threading."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

PACKETS_SCRIPT = """
import json, os, sys
os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # one core: the decoder runs without frame threads
from tracking.images import frames
fs = list(frames(sys.argv[1], packets=True))
print(json.dumps([[f.packet is not None, f.keyframe] for f in fs]))
"""


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="needs Linux CPU affinity")
def test_every_frame_carries_its_packet_on_one_core(installation: Path) -> None:
    """A decoder without delay returns a packet's frame at once: the packet must be there already."""
    out = subprocess.run([sys.executable, "-c", PACKETS_SCRIPT, str(installation / "cam-port.mp4")],
                         capture_output=True, text=True, check=True, cwd=Path(__file__).resolve().parents[2])
    flags = json.loads(out.stdout)
    assert len(flags) > 10
    assert all(has_packet for has_packet, _ in flags)  # before the fix: none had one, and JPEGs were recorded
    assert flags[0][1]  # the stream opens with a keyframe


def _turned_copy(source: Path, out: Path, degrees: int, count: int) -> list:
    """The source's first count frames' grey pixels stored turned back by `degrees` (lossless H.264), with a display
    rotation of `degrees`, as a phone filming in portrait writes them: what a player shows is the source."""
    import av
    import numpy as np

    from tracking.images import frames

    upright = [f.gray for _, f in zip(range(count), frames(source), strict=False)]
    with av.open(str(out), "w") as container:
        stream = container.add_stream("libx264", rate=15, options={"qp": "0", "preset": "ultrafast"})
        stream.height, stream.width = np.rot90(upright[0], -degrees // 90).shape
        stream.pix_fmt = "yuv444p"  # lossless luma at any turn
        stream.set_display_rotation(degrees)
        for gray in upright:
            stored = np.rot90(gray, -degrees // 90)  # the luma plane as it is, grey chroma: no range conversion
            planes = np.stack([stored, np.full_like(stored, 128), np.full_like(stored, 128)])
            container.mux(stream.encode(av.VideoFrame.from_ndarray(planes, format="yuv444p")))
        container.mux(stream.encode())
    return upright


@pytest.mark.parametrize("degrees", [90, -90, 180])
def test_a_video_with_a_display_rotation_is_read_upright_as_players_show_it(installation: Path, tmp_path: Path,
                                                                            degrees: int) -> None:
    """A portrait phone video stores its pixels landscape and a rotation: read unturned, its frames would not fit
    the calibration made from the same camera (as OpenCV shows its frames and photos), or would be read sideways."""
    import numpy as np

    from tracking.camera import load_camera
    from tracking.images import frames, open_video, turned
    from tracking.rig import load_rig

    turned_path = tmp_path / f"turned{degrees}.mp4"
    upright = _turned_copy(installation / "cam-port.mp4", turned_path, degrees, 6)
    read = list(frames(turned_path, keep_color=True, packets=True))
    assert len(read) == len(upright)
    for got, want in zip(read, upright, strict=True):
        assert got.gray.shape == want.shape and np.array_equal(got.gray, want)
        assert got.bgr.shape[:2] == want.shape
        assert got.packet is None  # recorded as an image: the recording's video decoder would show it unturned
    with open_video(turned_path) as turned_video, open_video(installation / "cam-port.mp4") as plain:
        assert turned(turned_video) and not turned(plain)  # the live server's budget takes it for pictures
    rig = load_rig(installation / "rig.yaml")
    entry = next(c for c in rig.cameras if c.name == "cam-port")
    camera = load_camera(rig.resolve(entry.calibration))
    assert camera.size_problem(read[0].gray.shape[1], read[0].gray.shape[0]) is None
