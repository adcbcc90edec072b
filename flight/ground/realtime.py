"""Real-time scheduling for the streamer while it flies, when the system allows it.

On a machine whose cores are all busy, the kernel's fair scheduler shares them out in
slices of milliseconds: measured here with 4 busy processes on 2 cores, 50 Hz setpoints
came 32 ms late at the 99th percentile and stalled for up to 0.4 s. A ground station is
a real-time program, so the streamer asks for the round-robin real-time policy
(``SCHED_RR``, a low priority) for its main thread and the threads it starts afterwards
(the GCS heartbeat, the meta.json writer: threads inherit the policy, and sharing the
interpreter lock with a thread of lower priority would let that thread hold up the main
one). It sleeps between setpoints, so it takes a small share of one core; the kernel's
real-time throttling (95 % of each second by default) bounds the rest. Without the
permission (``CAP_SYS_NICE`` or an ``RLIMIT_RTPRIO``) nothing changes, and ``meta.json``
says so. `restore_scheduling` puts the calling thread back to the normal policy.
"""

from __future__ import annotations

import os

__all__ = ["REALTIME_PRIORITY", "raise_priority", "restore_scheduling"]

#: SCHED_RR priority: the lowest real-time level bar one, below the kernel's own threads.
REALTIME_PRIORITY = 2


def raise_priority() -> str:
    """Switch the calling thread to SCHED_RR; returns what it runs with, for meta.json."""
    if not hasattr(os, "sched_setscheduler"):
        return "normal (no real-time scheduling on this system)"
    try:
        os.sched_setscheduler(0, os.SCHED_RR, os.sched_param(REALTIME_PRIORITY))
    except OSError as error:
        return f"normal (real-time scheduling not permitted: {error.strerror or error})"
    return f"SCHED_RR priority {REALTIME_PRIORITY}"


def restore_scheduling() -> None:
    """Put the calling thread back to the normal policy (harmless when it never left)."""
    if hasattr(os, "sched_setscheduler"):
        try:
            if os.sched_getscheduler(0) != os.SCHED_OTHER:
                os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        except OSError:
            pass
