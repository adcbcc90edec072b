"""A warning when the rotor speeds stay zero while the vehicle is armed.

The estimator needs the rotor speeds. Some vehicles report ESC telemetry whose rpm stays
0 even with the motors spinning: ESCs without telemetry wired to the autopilot, and
ArduCopter SITL, whose ESC rpm is 0 unless ``SIM_VIB_MOT_MAX`` is set, and then a stand-in
(the motor command × ``SIM_VIB_MOT_MAX`` × 60, linear in the command where the thrust is
not), never the rotor speed. A log of such a flight cannot be estimated from its ESC rpm,
so the operator is told during the flight, not after. Without ESC telemetry at all the
readers take the motor outputs (SERVO_OUTPUT_RAW, which the streamer asks for) through the
vehicle file's ``[motor]`` curve: ``vehicle/configs/sitl_quad.parm`` turns SITL's ESC
telemetry off (``SIM_ESC_TELEM 0``) for that.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from mavsysid.flight.ground.link_state import VehicleState

__all__ = ["RotorWatch"]

_ESC = ("ESC_TELEMETRY_1_TO_4", "ESC_TELEMETRY_5_TO_8")


class RotorWatch:
    """Warns once when ESC rpm stayed 0 for ``after`` streamer s while armed.

    Parameters
    ----------
    vehicle : VehicleState
        The link's vehicle (armed or not).
    say : callable
        Receives the one-line warning.
    after : float
        Armed seconds of all-zero rpm before warning, s.

    Use `on_message` as a link listener.
    """

    def __init__(self, vehicle: VehicleState, say: Callable[[str], None],
                 after: float = 3.0) -> None:
        self.vehicle, self.say, self.after = vehicle, say, after
        self.warned = False
        self._zero_since: float | None = None

    def on_message(self, msg: Any, t: float) -> None:
        """Check one message (a link listener)."""
        if self.warned or msg.get_type() not in _ESC:
            return
        if not self.vehicle.armed or any(msg.rpm):
            self._zero_since = None
            return
        if self._zero_since is None:
            self._zero_since = t
        elif t - self._zero_since >= self.after:
            self.warned = True
            self.say(f"warning: the ESC telemetry reports rotor speeds of 0 rpm for "
                     f"{t - self._zero_since:.0f} s while armed: the pose log's rotor speeds "
                     "are zero and cannot be estimated from (ArduCopter SITL: its ESC rpm is "
                     "0, or with SIM_VIB_MOT_MAX a stand-in, never the rotor speed; turn its "
                     "ESC telemetry off with SIM_ESC_TELEM 0, as vehicle/configs/sitl_quad.parm "
                     "does, and the motor outputs are read instead)")
