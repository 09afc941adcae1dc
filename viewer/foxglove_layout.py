"""A Foxglove layout for an installation's archive (or its live stream, `topside live --foxglove`).

Cameras on the left (each image with its marker outlines and calibration), the 3-D scene in the jacket frame from
the archive's transforms in the middle, and on the right the offsets Δx and Δy of every cone with the ±150 mm band
and each estimate's ±2σ, then the cameras' health table and the event log.

docs/foxglove-layout.json is this layout for the demo's installation (cones A-D, four cameras); for another rig:

    python -m viewer.foxglove_layout rig.yaml > layout.json

The bands come from one small user script per cone (Foxglove runs it in the browser): its output topic
/studio_script/bands/<cone> carries the offsets, their ±2σ bounds and the tolerance.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from pathlib import Path

import foxglove.layouts as fl

from tracking.rig import Rig, load_rig
from viewer.recording import CONE_COLORS, TOLERANCE_M

SCRIPT_PREFIX = "/studio_script/bands"  # the user scripts' output topics: not in the archive, made by Foxglove
FIXED_FRAME = "jacket"
TOLERANCE_COLOR = "#e62828"
SIGMA_ALPHA = "80"  # hex alpha of a ±2σ bound's colour: half as strong as its estimate's
PLOTTED_AXES = ("dx", "dy")  # the horizontal offsets, what the tolerance applies to
AXIS_TITLES = {"dx": "Δx (to port) [m]", "dy": "Δy (astern) [m]"}
LAYOUT_SCALE_M = 60.0  # the 3-D view's distance from its target: a jacket of tens of metres fits


def band_script(cone: str) -> str:
    """TypeScript for Foxglove: a cone's offsets with their ±2σ bounds and the ±tolerance, in m."""
    return f"""// A cone's horizontal offsets, their +-2 sigma bounds and the +-{TOLERANCE_M:g} m tolerance, for plots.
import {{ Input }} from "./types";

export const inputs = ["/offsets/{cone}"];
export const output = "{SCRIPT_PREFIX}/{cone}";

type Output = {{
  dx: number; dx_low: number; dx_high: number;
  dy: number; dy_low: number; dy_high: number;
  tolerance: number; minus_tolerance: number;
}};

export default function script(event: Input<"/offsets/{cone}">): Output {{
  const m = event.message;
  return {{
    dx: m.dx, dx_low: m.dx - 2 * m.sdx, dx_high: m.dx + 2 * m.sdx,
    dy: m.dy, dy_low: m.dy - 2 * m.sdy, dy_high: m.dy + 2 * m.sdy,
    tolerance: {TOLERANCE_M:g}, minus_tolerance: -{TOLERANCE_M:g},
  }};
}}
"""


def hex_color(index: int, alpha: str = "") -> str:
    """The index-th cone's colour (viewer.recording's) as #rrggbb[aa]."""
    r, g, b = CONE_COLORS[index % len(CONE_COLORS)]
    return f"#{r:02x}{g:02x}{b:02x}{alpha}"


def offset_plot(axis: str, cones: Sequence[str]) -> fl.PlotPanel:
    """One axis of every cone, its ±2σ bounds thin, the ±tolerance in red; the legend above the plot, not on it."""
    paths = []
    for k, cone in enumerate(cones):
        topic = f"{SCRIPT_PREFIX}/{cone}"
        paths.append(fl.PlotSeries(value=f"{topic}.{axis}", label=f"{cone}", color=hex_color(k), line_size=1.5))
        for bound in ("low", "high"):
            paths.append(fl.PlotSeries(value=f"{topic}.{axis}_{bound}", label=f"{cone} ±2σ" if bound == "low" else "",
                                       color=hex_color(k, SIGMA_ALPHA), line_size=0.75, line_style="dashed"))
    if cones:
        topic = f"{SCRIPT_PREFIX}/{cones[0]}"
        paths += [fl.PlotSeries(value=f"{topic}.{name}", label="±150 mm" if name == "tolerance" else "",
                                color=TOLERANCE_COLOR, line_size=1.0) for name in ("tolerance", "minus_tolerance")]
    return fl.PlotPanel(title=f"{AXIS_TITLES[axis]}: estimate, ±2σ, ±150 mm", config=fl.PlotConfig(
        paths=paths, show_legend=True, legend_display="top", x_axis_label="capture time [s]",
        y_axis_label=f"{axis} [m]", is_synced=True))


def image_panel(camera: str) -> fl.ImagePanel:
    """A camera's frames with its marker outlines and ids, undistorted by its calibration."""
    base = f"/cameras/{camera}"
    return fl.ImagePanel(title=camera, config=fl.ImageConfig(image_mode=fl.ImageModeConfig(
        image_topic=f"{base}/image", calibration_topic=f"{base}/calibration",
        annotations={f"{base}/detections": fl.ImageAnnotationSettings(visible=True)})))


def scene_panel(cameras: Sequence[str]) -> fl.ThreeDeePanel:
    """The installation in the jacket frame: markers, cameras, topside (the archive's FrameTransforms), and every
    camera's frustum with its image."""
    topics = {f"/cameras/{c}/calibration": fl.BaseRendererCameraTopicSettings(visible=True) for c in cameras}
    topics |= {f"/cameras/{c}/image": fl.BaseRendererImageTopicSettings(visible=True) for c in cameras}
    return fl.ThreeDeePanel(title="installation (jacket frame)", config=fl.ThreeDeeConfig(
        follow_tf=FIXED_FRAME, fixed_frame=FIXED_FRAME, follow_mode="follow-none", topics=topics,
        camera_state=fl.ThreeDeeCameraState(distance=LAYOUT_SCALE_M, perspective=True, phi=60.0, theta_offset=-30.0,
                                            target=(0.0, 0.0, 0.0))))


def health_tabs(cameras: Sequence[str]) -> fl.TabContainer:
    """Every camera's health table (markers, reprojection error, frame interval), then the event log."""
    tabs = [fl.TabItem(title=c, content=fl.TablePanel(title=f"{c} health",
                                                      config=fl.TableConfig(topic_path=f"/cameras/{c}/health")))
            for c in cameras]
    tabs.append(fl.TabItem(title="events", content=fl.LogPanel(title="events", config=fl.LogConfig(
        topic_to_render="/log", show_time=True, show_level=True))))
    return fl.TabContainer(tabs=tabs)


def foxglove_layout(cameras: Sequence[str], cones: Sequence[str]) -> fl.Layout:
    """The layout for an installation with these cameras and cones."""
    images = fl.SplitContainer(direction="column", items=[fl.SplitItem(content=image_panel(c)) for c in cameras])
    right = fl.SplitContainer(direction="column", items=[
        *(fl.SplitItem(proportion=2, content=offset_plot(axis, cones)) for axis in PLOTTED_AXES),
        fl.SplitItem(proportion=2, content=health_tabs(cameras))])
    return fl.Layout(
        content=fl.SplitContainer(direction="row", items=[fl.SplitItem(proportion=1, content=images),
                                                          fl.SplitItem(proportion=2, content=scene_panel(cameras)),
                                                          fl.SplitItem(proportion=2, content=right)]),
        user_scripts={f"bands-{cone}": fl.UserScript(name=f"cone {cone} bands", source_code=band_script(cone))
                      for cone in cones})


def rig_layout(rig: Rig) -> fl.Layout:
    """The layout for a rig's cameras and cones (its pairs' cones and surveyed tips)."""
    return foxglove_layout([c.name for c in rig.cameras], rig.all_cones())


def layout_json(layout: fl.Layout) -> str:
    """The layout as the file Foxglove imports (indented, one trailing newline)."""
    return json.dumps(json.loads(layout.to_json()), indent=2, ensure_ascii=False) + "\n"


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: python -m viewer.foxglove_layout RIG.yaml > layout.json")
    sys.stdout.write(layout_json(rig_layout(load_rig(Path(sys.argv[1])))))
