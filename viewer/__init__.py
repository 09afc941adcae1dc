"""Rerun logging, blueprints, MCAP export and playback of what `tracking` measured."""

import os

# Live segments are written without an RRD footer (see viewer.session); rerun warns about that once per file, which
# over six hours floods the operator's console. Set before rerun is first imported; a user's RUST_LOG wins.
os.environ.setdefault("RUST_LOG", "warn,re_log_encoding::rrd::file_sink=error")
