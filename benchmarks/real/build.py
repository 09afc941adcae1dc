"""Build benchmarks/real/<session>/ from the real footage in ../shared/data/caliscope/ (four webcams, a hand-held
ChArUco board): a rig, the cameras' calibrations, their times files and the truth (the offset is zero: the board is
rigid), as `topside import-caliscope` writes them (tracking/caliscope.py says how). Run it again to rebuild them:

    .venv/bin/python benchmarks/real/build.py [--data ../shared/data/caliscope]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from tracking.caliscope import read_session, write_session

HERE = Path(__file__).resolve().parent
SESSIONS = ("charuco_calibration", "post_optimization")
DATA = HERE.parents[2] / "shared" / "data" / "caliscope"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, default=DATA, help="the caliscope folder of ../shared/data")
    args = parser.parse_args()
    for session in SESSIONS:
        print(write_session(read_session(args.data / session), HERE / session))


if __name__ == "__main__":
    main()
