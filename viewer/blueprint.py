"""The layout stored in every recording: a 2-D view per camera, the 3-D view, a plot per axis, a status panel."""

from __future__ import annotations

import numpy as np
import rerun.blueprint as rrb

from tracking.rig import Rig

EYE_OFFSET_M = np.array([-25.0, -45.0, 20.0])  # default 3-D eye: from ahead, starboard and above the cones
HEALTH_SERIES = {"markers": "markers found", "reprojection_error_px": "reprojection [px]",
                 "frame_age_s": "frame age [s]"}
AXIS_TITLES = {"dx": "Δx (to port) [m]", "dy": "Δy (astern) [m]", "dz": "Δz (up) [m]"}


def analysis_blueprint(rig: Rig, with_truth: bool) -> rrb.Blueprint:
    """Engineer's layout: cameras left, 3-D and status middle, offset (and error) plots right."""
    points = list(rig.cones.values()) or [m.center for m in rig.markers]
    centre = np.mean(np.array(points, dtype=float), axis=0)
    cameras = [rrb.Spatial2DView(origin=f"world/cameras/{c.name}", name=c.name) for c in rig.cameras]
    plots = [rrb.TimeSeriesView(origin=f"offsets/{axis}", name=title) for axis, title in AXIS_TITLES.items()]
    if with_truth:
        plots += [rrb.TimeSeriesView(origin=f"errors/{axis}", name=f"error {axis} [m]") for axis in AXIS_TITLES]
    health = rrb.Tabs(*(
        rrb.TimeSeriesView(origin="health", contents=[f"health/{c.name}/{series}" for c in rig.cameras], name=title)
        for series, title in HEALTH_SERIES.items()),
        rrb.TimeSeriesView(origin="uncertainty", name="estimate σ [m]"), name="camera health")
    middle = rrb.Vertical(
        rrb.Spatial3DView(origin="world", name="installation (jacket frame)", eye_controls=rrb.EyeControls3D(
            position=centre + EYE_OFFSET_M, look_target=centre, eye_up=[0.0, 0.0, 1.0])),
        rrb.Horizontal(rrb.TextDocumentView(origin="status", name="status"), health),
        row_shares=[3, 2])
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Grid(*cameras, name="cameras", grid_columns=2 if len(cameras) > 1 else 1),
            middle,
            rrb.Grid(*plots, grid_columns=2 if with_truth else 1, name="offsets"),
            column_shares=[3, 3, 3]),
        rrb.TimePanel(state="collapsed"),
        collapse_panels=True)
