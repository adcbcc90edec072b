"""One planning job: check the request, run the information-gathering planner (or the
paper's random baseline) with progress reports, and say how far a failed search got; and
the autopilot limits it plans within, from a parameter dump or read from the vehicle.

`run_plan` is what ``mavsysid plan`` and the demo call; tests call it directly.
`preview_plan` is the look before a flight that ``mavsysid plan`` prints: the plan's peaks
(speed, tilt, body rate, thrust) and the rotor saturation predicted by flying it on the
offline simulator with the vehicle file's nominal θ. `with_margins` holds part of a
vehicle's body-rate, yaw-acceleration and thrust envelope back from the planner;
`for_noise_met` sets its model to the noise the estimator met on a flight of the vehicle.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from mavsysid.planner.plan_request import check_request
from mavsysid.planner.plan_result import PlanProgress, PlanResult
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.autopilot_loop import AutopilotLoop, loop_parameter_names
from mavsysid.vehicle.config import VehicleConfig, load_vehicle
from mavsysid.vehicle.constants import GRAVITY
from mavsysid.vehicle.kinematic_limits import KinematicLimits
from mavsysid.vehicle.trajectory import Trajectory

from mavsysid.errors import InputError, JobFailedError

if TYPE_CHECKING:
    from mavsysid.estimation.results import NoiseMet

__all__ = ["SATURATION_WARNING", "AutopilotEnvelope", "PlanPreview", "ProgressCallback",
           "autopilot_limits", "describe_noise", "for_noise_met", "preview_plan", "progress_bar",
           "read_autopilot", "run_plan", "with_margins"]

#: Predicted rotor saturation (share of control ticks) above which `plan` warns: beyond it
#: the autopilot has no room to correct, and a vehicle whose θ differs saturates more.
SATURATION_WARNING = 0.01

#: `mavsysid.flight.autopilot_modes.Autopilot` names as the autopilots spell themselves.
_AUTOPILOT_NAMES = {"ARDUPILOT": "ArduPilot", "PX4": "PX4"}
#: Called with each progress report of a planning run.
ProgressCallback = Callable[[PlanProgress], None]


@dataclass(frozen=True)
class AutopilotEnvelope:
    """What a plan is made for, read from an autopilot (`read_autopilot`).

    Attributes
    ----------
    source : str
        Where it came from and its limits, in words (one line).
    limits : KinematicLimits
        The envelope (`mavsysid.flight.ground.autopilot_limits.limits_from_parameters`:
        correction limits included, so that the plan flies with no note).
    loop : AutopilotLoop or None
        Its closed loop (`mavsysid.vehicle.autopilot_loop`), when asked for: the loop
        parameters it reported, stock defaults for the rest.
    """

    source: str
    limits: KinematicLimits
    loop: AutopilotLoop | None = None


def autopilot_limits(source: str | Path, signing_key: bytes | None = None,
                     heartbeat_timeout: float = 30.0, say: Callable[[str], None] | None = None
                     ) -> tuple[str, KinematicLimits]:
    """The envelope of the autopilot that will fly a plan (``plan --autopilot-limits``):
    `read_autopilot`'s source and limits.

    Parameters
    ----------
    source, signing_key, heartbeat_timeout, say
        As for `read_autopilot`.
    """
    envelope = read_autopilot(source, signing_key, heartbeat_timeout, say)
    return envelope.source, envelope.limits


def read_autopilot(source: str | Path, signing_key: bytes | None = None,
                   heartbeat_timeout: float = 30.0, say: Callable[[str], None] | None = None,
                   loop: bool = False) -> AutopilotEnvelope:
    """The limits (and with ``loop`` the closed loop) of the autopilot that will fly a plan.

    Parameters
    ----------
    source : str or Path
        A parameter dump (`mavsysid.formats.parameter_file`), or a MAVLink link to the
        vehicle (``tcp:HOST:PORT``, ``udp:HOST:PORT``, ``udpout:HOST:PORT``,
        ``serial:DEVICE[:BAUD]``, a ``/dev/…`` device; a regular file of that name is read
        as a file): its parameters are then read live, as `mavsysid stream` reads them.
    signing_key : bytes, optional
        MAVLink 2 signing key for a vehicle that signs.
    heartbeat_timeout : float
        Wall seconds to wait for the vehicle's first heartbeat.
    say : callable, optional
        Receives one-line progress messages while connecting.
    loop : bool
        Also read its loop parameters and model its closed loop (``plan
        --autopilot-model``).

    Raises
    ------
    InputError
        An unreadable dump, or one without one autopilot's limits (one line naming it); a
        signing key with a dump.
    JobFailedError
        No vehicle answered on the link, or it reported none of its limits.
    """
    # The ground station's limit tables (and the MAVLink set-up they import) only here.
    from mavsysid.flight.ground.autopilot_limits import limits_from_parameters, limits_text
    from mavsysid.flight.ground.vehicle_contact import vehicle_limit_values
    from mavsysid.flight.mavlink_setup import parse_connect
    from mavsysid.formats.parameter_file import read_parameter_file

    text = str(source)
    is_link = False
    if not Path(text).is_file():
        try:
            parse_connect(text)
            is_link = True
        except InputError:
            pass  # not a link: read as a file, which says what is wrong with it
    if signing_key is not None and not is_link:
        raise InputError(f"--signing-key: only with --connect LINK, got the file {text}")
    if is_link:
        autopilot, values = vehicle_limit_values(text, signing_key, heartbeat_timeout, say,
                                                 loop=loop)
        limits = limits_from_parameters(values, text)[1]
        where = f"the {_AUTOPILOT_NAMES[autopilot.name]} vehicle on {text}"
    else:
        values = read_parameter_file(text)
        autopilot, limits = limits_from_parameters(values, text)
        where = f"the {_AUTOPILOT_NAMES[autopilot.name]} parameters in {text}"
    words = f"{where}: {limits_text(limits)}"
    if not loop:
        return AutopilotEnvelope(words, limits)
    kind = autopilot.name.lower()
    names = loop_parameter_names(kind)
    known = sum(name in values for name in names)
    return AutopilotEnvelope(f"{words}; its loop from {known} of {len(names)} parameters "
                             "(stock defaults for the rest)", limits,
                             AutopilotLoop.from_parameters(kind, values))


@contextmanager
def progress_bar(settings: PlannerSettings) -> Iterator[ProgressCallback]:
    """A tqdm bar on stderr fed by the planner's progress reports (off when not a tty).

    Parameters
    ----------
    settings : PlannerSettings
        Its sample or time budget sets the bar's total.
    """
    from tqdm import tqdm  # only the console script needs it

    by_samples = settings.max_samples is not None
    total = settings.max_samples if by_samples else settings.planning_time
    # disable=None: tqdm stays quiet when stderr is not a terminal (logs, pipes, CI).
    with tqdm(total=total, unit="sample" if by_samples else "s", file=sys.stderr,
              disable=None, leave=False, dynamic_ncols=True,
              bar_format=None if by_samples else "{l_bar}{bar}| {n:.0f}/{total:.0f} s{postfix}",
              ) as bar:

        def report(progress: PlanProgress) -> None:
            done = progress.samples if by_samples else min(progress.elapsed, float(total))
            bar.update(done - bar.n)
            best = "—" if progress.best_dopt is None else f"{progress.best_dopt:.3g}"
            # A dict keeps this order; keyword arguments would be sorted by name.
            bar.set_postfix({"vertices": progress.vertices, "beliefs": progress.beliefs,
                             "D-opt": best, "elapsed": f"{progress.elapsed:.1f} s"},
                            refresh=False)

        yield report


def run_plan(
    vehicle: str | Path | VehicleConfig, settings: PlannerSettings, random: bool = False,
    progress: bool | ProgressCallback = True, say: Callable[[str], None] | None = None,
) -> PlanResult:
    """Check a planning request and plan.

    Parameters
    ----------
    vehicle : str, Path or VehicleConfig
        Shipped vehicle name, TOML path, or a loaded configuration.
    settings : PlannerSettings
        Budget, planning time and/or sample count, box, start, seed.
    random : bool
        Use the paper's random baseline instead of the information-gathering planner.
    progress : bool or callable
        True: a progress bar on stderr (when it is a terminal); False: none; a callable:
        called with each `PlanProgress`.
    say : callable, optional
        Receives one line once the request is checked and the search starts (a run can
        take its whole planning time without a word otherwise).

    Raises
    ------
    InputError
        See `mavsysid.planner.plan_request.check_request`, and unknown or malformed
        vehicles.
    JobFailedError
        No feasible trajectory was found; the message says how long was searched and how
        large the graph grew.
    """
    config = vehicle if isinstance(vehicle, VehicleConfig) else load_vehicle(vehicle)
    # Checked here as well as by the planner, so that a refused request loads no planner.
    check_request(config, settings)
    if say is not None:
        limit = (f"{settings.planning_time:g} s" if np.isfinite(settings.planning_time)
                 else f"{settings.max_samples} samples")
        say(f"planning a {settings.budget:g} s flight for {config.name} ({limit})")
    if random:
        from mavsysid.planner.baseline import plan_random as planner
    else:
        from mavsysid.planner.rrbt import plan as planner
    last: list[PlanProgress] = []

    def track(report: ProgressCallback | None) -> ProgressCallback:
        def callback(p: PlanProgress) -> None:
            last[:] = [p]
            if report is not None:
                report(p)
        return callback

    try:
        if progress is True:
            with progress_bar(settings) as bar:
                return planner(config, settings, progress=track(bar))
        return planner(config, settings, progress=track(progress or None))
    except JobFailedError as error:
        text = str(error)
        if text.startswith("no feasible") or not last:
            raise
        p = last[0]
        raise JobFailedError(f"no feasible trajectory found in {p.elapsed:.1f} s "
                             f"({p.vertices} vertices, {p.edges} edges): {text}") from None


def for_noise_met(config: VehicleConfig, settings: PlannerSettings, met: NoiseMet | None
                  ) -> tuple[VehicleConfig, PlannerSettings]:
    """The planner's model and settings for the estimator that will answer.

    The planner predicts θ's covariance with the filter's own recursion; by default at the
    vehicle file's noise (its ``[noise]`` pose σ and process-noise densities) and a pose at
    `PlannerSettings.measurement_rate`. A flight of the vehicle tells what the filter
    actually met: the pose σ it used, the pose's rate and the unmodelled force and moment
    it fitted (`NoiseMet`, written by ``estimate`` as ``noise_met``). Planned at that noise,
    the predicted σ is the one ``estimate`` reports on a like flight, and the plan weighs
    what the estimator can resolve.

    Parameters
    ----------
    config : VehicleConfig
        The planner's vehicle.
    settings : PlannerSettings
    met : NoiseMet or None
        The noise met on a flight of this vehicle; None leaves both unchanged.

    Returns
    -------
    config : VehicleConfig
        With ``met``'s pose σ and densities as its noise.
    settings : PlannerSettings
        With ``met``'s pose rate as the measurement rate.
    """
    if met is None:
        return config, settings
    return met.applied_to(config), replace(settings, measurement_rate=met.pose_rate)


def describe_noise(met: NoiseMet) -> str:
    """``met`` in words, one line (without the source).

    Parameters
    ----------
    met : NoiseMet
        The noise the estimator met on a flight.
    """
    return (f"pose σ {1000 * met.position_sigma:.3g} mm, {np.degrees(met.attitude_sigma):.3g}° "
            f"at {met.pose_rate:.3g} Hz; unmodelled force {met.force_density:.3g} N·√s, "
            f"moment {met.moment_density:.3g} N·m·√s")


def with_margins(config: VehicleConfig, body_rate: float = 0.0,
                 yaw_acceleration: float = 0.0, thrust: float = 0.0) -> VehicleConfig:
    """``config`` with a share of its envelope held back from the planner.

    Parameters
    ----------
    config : VehicleConfig
    body_rate, yaw_acceleration : float
        Share of ``body_rate_max`` / ``yaw_acceleration_max`` left unused, in [0, 1).
    thrust : float
        Share of the thrust above hover (``thrust_max_ratio`` - 1) left unused, in [0, 1).

    Raises
    ------
    InputError
        A margin outside [0, 1).
    """
    from mavsysid.errors import InputError

    for name, value in (("body-rate", body_rate), ("yaw-acceleration", yaw_acceleration),
                        ("thrust", thrust)):
        if not 0.0 <= value < 1.0:
            raise InputError(f"--{name}-margin {value:g}: expected a share in [0, 1)")
    lim = config.limits
    return replace(config, limits=replace(
        lim, body_rate_max=(1.0 - body_rate) * lim.body_rate_max,
        yaw_acceleration_max=(1.0 - yaw_acceleration) * lim.yaw_acceleration_max,
        thrust_max_ratio=1.0 + (1.0 - thrust) * (lim.thrust_max_ratio - 1.0)))


@dataclass(frozen=True)
class PlanPreview:
    """What a plan asks of the vehicle (`preview_plan`).

    Attributes
    ----------
    speed : float
        Largest speed, m/s.
    tilt : float
        Largest lean of the thrust axis from the vertical, rad.
    body_rate : float
        Largest body rate ‖ω‖, rad/s.
    thrust : float
        Largest collective thrust over hover thrust (m g).
    saturation : float
        Share of the offline simulator's control ticks with a rotor command clipped at a
        limit, flying the plan with the vehicle file's nominal θ and motor lag.
    tracking_max : float
        Largest distance of the simulated vehicle from the plan, m.
    """

    speed: float
    tilt: float
    body_rate: float
    thrust: float
    saturation: float
    tracking_max: float


def preview_plan(trajectory: Trajectory, config: VehicleConfig) -> PlanPreview:
    """Peaks of ``trajectory`` (sampled at 100 Hz through the flatness map) and its
    rotor saturation on the offline simulator with ``config`` (`PlanPreview`).

    Parameters
    ----------
    trajectory : Trajectory
        The planned reference (flat outputs: position in m, world ENU, and yaw in rad,
        over ``trajectory.duration`` s).
    config : VehicleConfig
        The vehicle the plan is for: its nominal θ, mass, rotors and motor lag drive both
        the flatness map and the offline simulator.
    """
    from mavsysid.flight.offline.simulator import Simulator
    from mavsysid.vehicle.flatness import flat_to_state

    t = np.linspace(0.0, trajectory.duration, int(trajectory.duration * 100.0) + 1)
    state = flat_to_state(trajectory.flat_outputs(t), config)
    result = Simulator(config).run(trajectory)
    error = np.linalg.norm(result.states[:, 0:3] - result.reference_position, axis=1)
    return PlanPreview(
        speed=float(np.max(np.linalg.norm(state.velocity, axis=1))),
        tilt=float(np.max(np.arccos(np.clip(state.rotation[:, 2, 2], -1.0, 1.0)))),
        body_rate=float(np.max(np.linalg.norm(state.body_rates, axis=1))),
        thrust=float(np.max(state.thrust) / (config.mass * GRAVITY)),
        saturation=float(result.saturated_fraction), tracking_max=float(np.max(error)))
