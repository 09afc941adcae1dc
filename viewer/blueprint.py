"""The layout stored in every recording: a 2-D view per camera, the 3-D view, a plot per axis, a status panel."""

from __future__ import annotations

import rerun.blueprint as rrb

from tracking.rig import Rig

AXIS_TITLES = {"dx": "Δx (to port) [m]", "dy": "Δy (astern) [m]", "dz": "Δz (up) [m]"}


def analysis_blueprint(rig: Rig, with_truth: bool) -> rrb.Blueprint:
    """Engineer's layout: cameras left, 3-D and status middle, offset (and error) plots right."""
    cameras = [rrb.Spatial2DView(origin=f"world/cameras/{c.name}", name=c.name) for c in rig.cameras]
    plots = [rrb.TimeSeriesView(origin=f"offsets/{axis}", name=title) for axis, title in AXIS_TITLES.items()]
    if with_truth:
        plots += [rrb.TimeSeriesView(origin=f"errors/{axis}", name=f"error {axis} [m]") for axis in AXIS_TITLES]
    health = rrb.TimeSeriesView(origin="health", name="camera health")
    middle = rrb.Vertical(
        rrb.Spatial3DView(origin="world", name="installation (jacket frame)"),
        rrb.Horizontal(rrb.TextDocumentView(origin="status", name="status"), health),
        row_shares=[3, 2])
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Grid(*cameras, name="cameras", grid_columns=1 if len(cameras) <= 3 else 2),
            middle,
            rrb.Grid(*plots, grid_columns=2 if with_truth else 1, name="offsets"),
            column_shares=[2, 3, 3]),
        rrb.TimePanel(state="collapsed"),
        collapse_panels=True)
