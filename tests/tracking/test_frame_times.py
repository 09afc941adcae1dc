"""Times files (tracking.frame_times): a camera's per-frame capture times, read strictly, every mistake one line."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tracking.errors import InputError
from tracking.frame_times import FrameClock, read_frame_times
from tracking.rig import CameraEntry


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "cam.times.csv"
    path.write_text(text)
    return path


def test_times_by_frame_number_with_gaps(tmp_path: Path) -> None:
    times = read_frame_times(write(tmp_path, "frame,time\n2,10.5\n0,10.0\n3,10.7\n"))
    assert times[0] == 10.0 and np.isnan(times[1]) and times[2] == 10.5 and times[3] == 10.7
    clock = FrameClock(0.25, times)
    assert clock.capture(2, 999.0) == pytest.approx(10.75)  # the file's time, not the presentation time
    assert np.isnan(clock.capture(1, 0.0)) and np.isnan(clock.capture(9, 0.0))
    assert FrameClock(0.25).capture(5, 1.0) == 1.25  # no file: presentation time plus offset


@pytest.mark.parametrize(("text", "says"), [
    ("frame;time\n0;1.0\n", "missing column 'frame'"),
    ("frame,seconds\n0,1.0\n", "missing column 'time'"),
    ("frame,time\n0,1.0\n1.5,2.0\n", "line 3: frame"),
    ("frame,time\n0,1.0\n-1,2.0\n", "line 3: frame"),
    ("frame,time\n0,1.0\n1,abc\n", "line 3: time"),
    ("frame,time\n0,1.0\n0,2.0\n", "frame 0 is listed twice"),
    ("frame,time\n0,1.0\n1,1.0\n", "frame 1: time does not increase"),
    ("frame,time\n", "line 2: frame"),
])
def test_a_bad_times_file_is_one_line_naming_it(tmp_path: Path, text: str, says: str) -> None:
    path = write(tmp_path, text)
    with pytest.raises(InputError) as err:
        read_frame_times(path)
    assert says in str(err.value) and str(path) in str(err.value)
    assert "\n" not in str(err.value)


def test_a_missing_times_file_is_named(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="times file not found"):
        read_frame_times(tmp_path / "nope.csv")


def test_times_go_with_video_files_only() -> None:
    with pytest.raises(ValueError, match="times"):
        CameraEntry(name="c", calibration="c.yaml", source="0", times="c.csv")
    with pytest.raises(ValueError, match="times"):
        CameraEntry(name="c", calibration="c.yaml", source="rtsp://10.0.0.5/s", times="c.csv")
    assert CameraEntry(name="c", calibration="c.yaml", source="c.mp4", times="c.csv").times == "c.csv"
