"""Writing a Rerun recording file atomically: shared by every stage's ``--rrd``.

A reader sees the previous file or the complete new one: the recording goes to a temp
file beside the target and is renamed when its footer has been written. strict mode is
the caller's to use on every log call: by default rerun only warns about malformed data
(columns of unequal length, say) and drops it, which would leave a silently incomplete
file. Recording properties (which carry the wall-clock start time) and log time are off,
so only what the caller sends goes in.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import rerun as rr

__all__ = ["atomic_recording"]


@contextmanager
def atomic_recording(
    path: str | Path, application_id: str, recording_id: str, name: str,
    blueprint: Any | None = None,
) -> Iterator[rr.RecordingStream]:
    """A recording stream saving to ``path``, which appears only when the block succeeds.

    Parameters
    ----------
    path : str or Path
        The ``.rrd`` file.
    application_id : str
        Rerun application id.
    recording_id : str
        Rerun recording id (fixed, so a recording is reproducible).
    name : str
        Recording name shown in the viewer.
    blueprint : rerun blueprint, optional
        Viewer layout sent first.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    rec = rr.RecordingStream(application_id, recording_id=recording_id, send_properties=False)
    try:
        rec.set_log_time_enabled(False)
        rec.save(tmp, default_blueprint=blueprint)
        rec.send_recording_name(name)
        yield rec
        rec.flush()
        # Closes the file sink, writing the footer; without it a reader may see a truncated file.
        rec.disconnect()
        os.replace(tmp, path)
    except BaseException:
        rec.disconnect()
        Path(tmp).unlink(missing_ok=True)
        raise
