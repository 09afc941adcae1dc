"""The estimator: fusion of every camera into the topside's rigid pose relative to the jacket, over time.

One Kalman filter for the whole installation. Its state holds the topside (12,): translation t and
small rotation ω of the topside frame in the jacket frame, and their rates; and every camera (12,
each): its pose in the jacket frame as an error about a nominal T_jacket_camera (rotation δθ, position
δp) and its rates, with a motion prior from the rig's mount (fixed, vessel, drone). A camera's rates
revert to zero within CAMERA_RATE_TAU_S, and a camera on a rigid mount gets only the process noise its
own images show: the jacket markers' image motion measures how much it moves (a vessel in calm water,
barely), so a still camera's pose, and with it the swing about its one far marker that the corners
hardly see, is averaged over many seconds instead of a fraction of one.

A camera frame is measured by its markers' corners: each marker's four undistorted corners against
their projection through T_camera_jacket (jacket markers) or T_camera_jacket · T_jacket_topside
(topside markers); the camera first, from its jacket corners, then the topside. A far camera's
poorly seen marker tilt is thus averaged into the camera's pose over time instead of turning depth
into height and sideways offset at every frame, and the markers' precise bearings do the measuring.
Body poses (pose.estimate_body_pose) only place a camera or the topside at first sight.

Pair offsets (topside marker S displaced from its mated position, jacket frame) are accepted too:
to first order in ω, o = (R - I) r_S + t ≈ t - [r_S]× ω, linear in the state.

A marker's corners seen by one camera carry, besides white noise, an error that stays while the marker's image
stays: the sub-pixel phase of its edges, the blur of its own data cells into the border, and the stream's coding
of a still picture do not change from frame to frame. Each view (camera, marker) therefore has 8 bias states, one
per corner coordinate, which renew as the marker's image moves (VIEW_BIAS_RENEW_PX). A still camera's view of a
still jacket marker then tells the filter its pose to the bias's σ, however long it looks, instead of averaging
a fixed error away as if it were noise (evidence in docs/method.md#fusion-the-default). Part of the error stays
wherever the image goes, as long as it keeps its shape: the plate's edge and what lies beyond it, the code cells
beside the border, the blur across a cell. So each view has 8 more, which renew as its image's shape changes
(VIEW_SHAPE_BIAS_PX, VIEW_SHAPE_RENEW): a far stern camera following a topside across its picture for minutes
averages the first part away, not the second.

What the rig states but footage is not trusted to tell widens σ rather than hiding in it. Each marker's survey
error (survey_sigma) is a consider state (ConsiderStates): never estimated, its prior kept, its cross-covariance
carried, so a marker's error stays in σ however many frames see it. A camera's clock σ (time_offset_sigma) widens
its topside corners' noise by their motion over it, and every estimate's σ by the topside's motion over the largest
clock σ of the cameras it rests on (clock_bound).

Measurements are applied at their capture times (cameras need no synchronisation), and the offset
at every cone follows from the topside pose, including cones no camera sees. Corners far off are
down-weighted (Huber-like), markers and pair offsets gated by their Mahalanobis distance. Offline,
a Rauch-Tung-Striebel pass smooths the run.

Modules, in the order a frame meets them: noise (every σ, gate and time constant; process noise), process (the state
between captures), state (what x and P hold; the Kalman update), measurements (corners and pair offsets), hypotheses
and placement (a camera's and the topside's first sight), filter (TopsideFilter, the cone estimates), smoother (the
RTS passes), modes (the estimators by name).
"""

from tracking.estimator.filter import FilterReport, TopsideFilter
from tracking.estimator.measurements import Measurement, frames, preferred
from tracking.estimator.modes import ESTIMATORS, filter_frame, fused_estimates
from tracking.estimator.noise import CameraMotion, FilterTuning
from tracking.estimator.smoother import smoothed_estimates
from tracking.estimator.state import cone_points, point_offset_matrix

__all__ = ["ESTIMATORS", "CameraMotion", "FilterReport", "FilterTuning", "Measurement", "TopsideFilter",
           "cone_points", "filter_frame", "frames", "fused_estimates", "point_offset_matrix", "preferred",
           "smoothed_estimates"]
