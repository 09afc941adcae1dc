"""The layout stored in every recording: a 2-D view per camera, the 3-D view, a plot per axis, a status panel."""

from __future__ import annotations

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
from rerun import bindings

from tracking.rig import Rig
from viewer.recording import TIMELINE

EYE_OFFSET_M = np.array([-28.0, -62.0, 12.5])  # default 3-D eye, from the cones' centre: ahead, starboard and above,
LOOK_OFFSET_M = np.array([8.0, -8.0, -1.0])  # looking past the centre towards the stern cameras: the whole jacket,
# the topside above it and the cameras' frusta beside it in view (closer and lower, the demo's showed two legs and no
# camera)
HEALTH_SERIES = {"markers": "markers found", "reprojection_error_px": "reprojection [px]",
                 "frame_age_s": "frame age [s]"}
AXIS_TITLES = {"dx": "Δx (to port) [m]", "dy": "Δy (astern) [m]", "dz": "Δz (up) [m]"}
NO_LEGEND = rrb.PlotLegend(visible=False)  # a legend sits on the data; the key view names the colours instead


class LayoutSender:
    """Sends a recording's successive layouts through one blueprint stream.

    rerun-sdk 0.41's `send_blueprint` builds each layout in a new blueprint stream that is never freed (0.7-2.4 MB
    a call; a superintendent whose drones swap cones would grow for six hours). This sender keeps one stream and
    logs every layout into it at the next step of the "blueprint" timeline; each send drains it through a fresh
    memory sink, which also repeats the store's info, so a segment file that receives a layout can open alone.
    The previous layout's containers and views are cleared as the next is logged: left in the store, the viewer warns
    of "broken references" in a notice that covered a cone's column on the superintendent's tablet.
    """

    def __init__(self, application_id: str) -> None:
        self._stream = rr.RecordingStream._from_native(bindings.new_blueprint(
            application_id=application_id, make_default=False, make_thread_default=False, default_enabled=True))
        self._step = 0
        self._paths: list[str] = []  # the blueprint paths of the layout logged last

    def send(self, rec: rr.RecordingStream, blueprint: rrb.Blueprint, make_active: bool = True,
             make_default: bool = False) -> None:
        """The layout to the recording's sinks (file and viewer), made active there."""
        memory = self._stream.memory_recording()  # a new sink: it gets the store's info, then this layout
        self._stream.set_time("blueprint", sequence=self._step)
        paths = blueprint_paths(blueprint)
        for path in set(self._paths) - set(paths):
            self._stream.log(path, rr.Clear(recursive=True))
        self._paths = paths
        blueprint._log_to_stream(self._stream)
        self._stream.flush()
        bindings.send_blueprint(memory.storage, make_active, make_default, recording=rec.to_native())
        self._step += 1


def blueprint_paths(blueprint: rrb.Blueprint) -> list[str]:
    """The store paths of a layout's containers and views (container/<id>, view/<id>)."""
    paths = []
    pending = [blueprint.root_container] if hasattr(blueprint, "root_container") else []
    while pending:
        item = pending.pop()
        paths.append(item.blueprint_path())
        if isinstance(item, rrb.Container):  # a view's `contents` is its query, not children
            pending += list(item.contents)
    return paths


def analysis_blueprint(rig: Rig, with_truth: bool) -> rrb.Blueprint:
    """Engineer's layout: cameras left, 3-D and status middle, offset (and error) plots right."""
    points = list(rig.cones.values()) or [m.center for m in rig.markers]
    centre = np.mean(np.array(points, dtype=float), axis=0)
    cameras = [rrb.Spatial2DView(origin=f"world/cameras/{c.name}", name=c.name) for c in rig.cameras]
    plots = [rrb.TimeSeriesView(origin=f"offsets/{axis}", name=title, plot_legend=NO_LEGEND)
             for axis, title in AXIS_TITLES.items()]
    if with_truth:
        plots += [rrb.TimeSeriesView(origin=f"errors/{axis}", name=f"error {title}", plot_legend=NO_LEGEND)
                  for axis, title in AXIS_TITLES.items()]
    health = rrb.Tabs(*(
        rrb.TimeSeriesView(origin="health", contents=[f"health/{c.name}/{series}" for c in rig.cameras], name=title,
                           plot_legend=NO_LEGEND)
        for series, title in HEALTH_SERIES.items()),
        rrb.TimeSeriesView(origin="uncertainty", name="estimate 1σ [m]", plot_legend=NO_LEGEND),
        rrb.TextLogView(origin="health", contents=[f"health/{c.name}/video/events" for c in rig.cameras],
                        name="video problems"), name="camera health")
    middle = rrb.Vertical(
        rrb.Spatial3DView(origin="world", name="installation (jacket frame)", eye_controls=rrb.EyeControls3D(
            position=centre + EYE_OFFSET_M, look_target=centre + LOOK_OFFSET_M, eye_up=[0.0, 0.0, 1.0])),
        rrb.Horizontal(rrb.TextDocumentView(origin="status", name="status"), health),
        row_shares=[3, 2])
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Grid(*cameras, name="cameras", grid_columns=2 if len(cameras) > 1 else 1),
            middle,
            rrb.Vertical(rrb.TextDocumentView(origin="key", name="key to the plots' colours"),
                         rrb.Grid(*plots, grid_columns=2 if with_truth else 1, name="offsets"), row_shares=[1, 9]),
            column_shares=[3, 3, 3]),
        rrb.TimePanel(state="collapsed", timeline=TIMELINE),  # capture time, not a camera's frame numbers
        collapse_panels=True)
