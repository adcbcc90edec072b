"""Meeting a vehicle on a MAVLink link, and reading its limits without flying.

`meet_vehicle` is how every ground-side job starts on a `MavlinkLink`: the GCS heartbeat
on, the vehicle's first HEARTBEAT, an autopilot we speak, no signing mismatch.
`vehicle_limit_values` uses it to read the position-controller limit parameters
(`mavsysid.flight.ground.autopilot_limits.parameter_names`) for ``plan --autopilot-limits
LINK``: it records nothing and changes nothing.
"""

from __future__ import annotations

from collections.abc import Callable

from mavsysid.flight.autopilot_modes import Autopilot
from mavsysid.flight.ground.autopilot_limits import limit_parameters, parameter_names
from mavsysid.flight.ground.link_state import VehicleState
from mavsysid.flight.ground.mavlink_link import MavlinkLink
from mavsysid.flight.ground.parameter_session import ParameterSession
from mavsysid.vehicle.autopilot_loop import loop_parameter_names

from mavsysid.errors import JobFailedError

__all__ = ["meet_vehicle", "vehicle_limit_values"]


def meet_vehicle(link: MavlinkLink, timeout: float, refused: str,
                 progress: Callable[[str], None] | None = None,
                 watch: bool = False) -> VehicleState:
    """Start the GCS heartbeat and wait for a vehicle we can talk to.

    Parameters
    ----------
    link : MavlinkLink
    timeout : float
        Wall seconds to wait for its first HEARTBEAT (`MavlinkLink.wait_heartbeat`).
    refused : str
        What does not happen when this fails, the head of each refusal ("flight refused").
    progress : callable, optional
        Gets "waiting for …" lines.
    watch : bool
        Set the link's ``watch_heartbeat`` once the first heartbeat came.

    Raises
    ------
    JobFailedError
        No heartbeat; an autopilot that is neither ArduPilot nor PX4; a vehicle that signs
        its messages while we cannot (one line each, after ``refused``).
    """
    if progress is not None:
        progress(f"waiting for a vehicle heartbeat on {link.connect}")
    link.start_heartbeat()
    v = link.wait_heartbeat(timeout, progress)
    link.watch_heartbeat = watch
    if v.autopilot is None:
        raise JobFailedError(f"{refused}: the vehicle's autopilot "
                             f"({link.enum_name('MAV_AUTOPILOT', v.autopilot_id)}) is "
                             "neither ArduPilot nor PX4")
    link.poll(0.3)  # a few more messages: is the vehicle signing?
    if (problem := link.signing_problem()) is not None:
        raise JobFailedError(f"{refused}: {problem}")
    return v


def vehicle_limit_values(connect: str, signing_key: bytes | None = None,
                         heartbeat_timeout: float = 30.0,
                         say: Callable[[str], None] | None = None,
                         loop: bool = False) -> tuple[Autopilot, dict[str, float]]:
    """Read the limit parameters (`parameter_names`) from the vehicle on ``connect``.

    Parameters
    ----------
    connect : str
        A MAVLink link (`MavlinkLink`: ``tcp:HOST:PORT``, ``udp:HOST:PORT``, a serial
        device, …).
    signing_key : bytes, optional
        32-byte MAVLink 2 signing key, for a vehicle that signs.
    heartbeat_timeout : float
        Wall seconds to wait for the vehicle's first heartbeat.
    say : callable, optional
        Receives one-line progress messages.
    loop : bool
        Also read its position- and attitude-controller parameters
        (`mavsysid.vehicle.autopilot_loop.loop_parameter_names`).

    Returns
    -------
    tuple
        The vehicle's autopilot, and name → value (parameter units) of those it answered.

    Raises
    ------
    InputError
        A malformed link string.
    JobFailedError
        No vehicle, one we cannot talk to, or one that answered none of its limits.
    """
    with MavlinkLink(connect, signing_key=signing_key) as link:
        vehicle = meet_vehicle(link, heartbeat_timeout, "autopilot limits not read", say)
        autopilot = vehicle.autopilot
        assert autopilot is not None  # meet_vehicle refuses any other
        names = parameter_names(autopilot)
        if loop:
            names += loop_parameter_names(autopilot.name.lower())
        values = ParameterSession(link).read(names)
    if not any(p.name in values for p in limit_parameters(autopilot)):
        shown = ", ".join(p.name for p in limit_parameters(autopilot)[:3])
        raise JobFailedError(f"autopilot limits not read: the vehicle on {connect} answered "
                             f"none of its position-controller limits ({shown}, …)")
    return autopilot, values
