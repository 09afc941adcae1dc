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
