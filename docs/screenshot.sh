#!/usr/bin/env bash
# Screenshot a Rerun recording with the real (native) Rerun viewer, headless, with the
# recording's stored blueprint, paused at a chosen capture time.
#
#   docs/screenshot.sh RECORDING.rrd OUT.png [TIME]
#
# TIME: a value on the timeline (seconds for duration/timestamp timelines, absolute, clamped to the
#       data's range; an index for sequence ones), or a fraction of the range with a leading "f"
#       (e.g. f0.75, the default).
# Env:  SIZE=1600x1000 (window size in points; the PNG is this many pixels)
#       SETTLE=5       (seconds to wait after seeking, so on-demand chunks arrive and render)
#       VIEW=<view name> (only that view, e.g. VIEW="installation (jacket frame)"; default: the whole window)
#       TIMELINE=capture_time, PY=<python with rerun-sdk> (default: the project venv),
#       RERUN=<rerun viewer binary> (default: the one inside PY's rerun-sdk)
#
# Needs (Debian): mesa-vulkan-drivers + libvulkan1 (llvmpipe/lavapipe Vulkan, no GPU or X needed),
# and the project venv (rerun-sdk, whose `rerun` binary has the headless viewer).
#
# Why not `rerun --headless --screenshot-to`: that takes the screenshot a fixed 10 frames after
# start-up, without waiting for data. A local .rrd is first registered with the viewer's built-in
# catalog server and only then streamed back to the viewer, so a large recording (demo.rrd, 100 MB)
# is not there yet: the PNG shows "Failed to load File: ...: Data source finished without loading a
# recording" (the file source has handed over to the catalog stream, which has not arrived yet).
# Small recordings load in time, but the cursor is then at the start and playing.
# Instead, run the headless viewer as a server and drive it with rerun.experimental.ViewerClient:
# open the file, wait until nothing is loading, seek + pause, wait, save_screenshot.
set -euo pipefail

if [[ $# -lt 2 ]]; then
    sed -n '2,14p' "$0" >&2
    exit 2
fi
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
RRD="$(realpath "$1")"
OUT="$(realpath -m "$2")"
TIME="${3:-f0.75}"
SIZE="${SIZE:-1600x1000}"
SETTLE="${SETTLE:-5}"
TIMELINE="${TIMELINE:-capture_time}"
VIEW="${VIEW:-}"
PY="${PY:-$HERE/../.venv/bin/python}"
# The real viewer binary, not the venv's `rerun` wrapper: the wrapper runs it as a child process,
# so killing the wrapper would leave the viewer running.
RERUN="${RERUN:-$("$PY" -c 'import os, rerun_cli; print(os.path.join(os.path.dirname(rerun_cli.__file__), "rerun"))')}"
[[ -f "$RRD" ]] || { echo "no such recording: $RRD" >&2; exit 2; }
mkdir -p "$(dirname "$OUT")"

# The viewer wants a private runtime dir (else: "XDG_RUNTIME_DIR is invalid or not set"; harmless).
TMP="$(mktemp -d)"
chmod 700 "$TMP"
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$TMP}"
PORT="$("$PY" -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')"

# The viewer decodes H.264 video streams with an ffmpeg executable on PATH (the project's, if the system has none).
export PATH="$("$PY" -c 'import os; from viewer.playback import viewer_env; print(viewer_env()["PATH"])')"
"$RERUN" --headless --renderer vulkan --window-size "$SIZE" --bind 127.0.0.1 --port "$PORT" \
    --hide-welcome-screen >"$TMP/viewer.log" 2>&1 &
VIEWER=$!
trap 'kill "$VIEWER" 2>/dev/null || true; wait "$VIEWER" 2>/dev/null || true; rm -rf "$TMP"' EXIT

if ! "$PY" - "$PORT" "$RRD" "$OUT" "$TIME" "$TIMELINE" "$SETTLE" "$VIEW" <<'EOF'
import os, sys, time
from rerun.experimental import ViewerClient

port, rrd, out, when, timeline, settle, view_name = sys.argv[1:8]
deadline = time.monotonic() + 60
while True:  # the viewer takes a moment to listen
    try:
        viewer = ViewerClient.connect(f"rerun+http://127.0.0.1:{port}/proxy")
        viewer.get_state()
        break
    except Exception:
        if time.monotonic() > deadline:
            raise
        time.sleep(0.5)

viewer.open(rrd)
deadline = time.monotonic() + 300
while True:  # 'open' returns after ~10 s at most; poll until the chunk index has arrived
    state = viewer.get_state()
    rec = next((r for r in state.recordings if r.store_id == state.active_recording), None)
    if not state.loading and rec is not None and any(t.name == timeline and t.end is not None for t in rec.timelines):
        break
    if not state.loading and rec is not None and rec.timelines and time.monotonic() > deadline - 280:
        sys.exit(f"no timeline {timeline!r} in {rrd}: {[t.name for t in rec.timelines]} (set TIMELINE=)")
    if time.monotonic() > deadline:
        sys.exit(f"recording did not load: loading={state.loading}")
    time.sleep(0.5)

tl = next(t for t in rec.timelines if t.name == timeline)
ns = tl.start + float(when[1:]) * (tl.end - tl.start) if when.startswith("f") else float(when) * 1e9
ns = int(min(max(ns, tl.start), tl.end))
kind = {"duration": "duration", "timestamp": "timestamp", "sequence": "sequence"}[tl.time_type]
value = ns if kind == "sequence" else ns / 1e9
viewer.set_time(timeline, play_state="paused", **{kind: value})
time.sleep(float(settle))  # chunks at the cursor are fetched on demand, then rendered
state = viewer.get_state()
for view in state.views:
    for report in view.reports:
        print(f"view {view.name!r} ({view.origin}): {report.severity}: {report.summary}", file=sys.stderr)
view_id = None
if view_name:
    view_id = next((v.view_id for v in state.views if v.name == view_name), None)
    if view_id is None:
        sys.exit(f"no view {view_name!r}: {[v.name for v in state.views]}")
viewer.save_screenshot(out, view_id)
print(f"{out}: {os.path.basename(rrd)} at {timeline}={value} ({view_name or f'{len(state.views)} views'})")
EOF
then
    echo "--- viewer log ---" >&2
    cat "$TMP/viewer.log" >&2
    exit 1
fi
