"""What a simulated-vehicle session is asked to do (`SimSettings`) and did (`SimSummary`).

Kept apart from `mavsysid.flight.simvehicle.endpoint`, which re-exports both.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mavsysid.flight.autopilot_modes import Autopilot
from mavsysid.flight.simvehicle.clock import ClockStats
from mavsysid.vehicle.model_effects import ModelEffect

__all__ = ["SimSettings", "SimSummary"]


@dataclass(frozen=True)
class SimSettings:
    """How to simulate.

    Attributes
    ----------
    autopilot : Autopilot
        Personality: ArduPilot Copter or PX4.
    speedup : float
        Sim seconds per wall second.
    ekf_delay : float
        Sim seconds before the EKF has a position.
    start : tuple of 3 float
        Start position on the ground, m, world ENU.
    seed : int
        Seed of the published and logged noise.
    theta_scale : tuple of 6 float
        True θ = nominal θ × these factors (c_T, c_D, c_M, j_x, j_y, j_z).
    sensor_noise : bool
    duration : float or None
        Stop after this many sim seconds.
    signing_key : bytes or None
        32-byte MAVLink 2 secret key.
    truth_log : Path or None
        Directory for ``truth.csv``, ``pose.csv`` and ``meta.json``.
    deny_arm : bool
        Refuse every arming request.
    land_detector_fails : bool
        A touchdown in LAND goes undetected: the vehicle stays armed on the ground and
        refuses a disarm unless forced (ArduCopter in strong wind).
    pilot_mode : (str, float) or None
        At this sim time switch to this mode, as a pilot's switch would.
    silent_after : float or None
        At this sim time stop sending anything (a lost link).
    weak_motor : (int, float, float) or None
        Motor output N (1-based, the autopilot's numbering) makes F of its thrust from sim
        time S on: (N, F, S) (`mavsysid.flight.simvehicle.physics.SimVehicle.weaken`).
    hidden_effects : tuple of ModelEffect
        Catalogue effects acting on the truth that the model does not know.
    lockstep : bool
        Lock-step with a ground station that acknowledges frames (tests, benches).
    """

    autopilot: Autopilot = Autopilot.ARDUPILOT
    speedup: float = 1.0
    ekf_delay: float = 2.0
    start: tuple[float, float, float] = (0.0, 0.0, 0.0)
    seed: int = 0
    theta_scale: tuple[float, ...] = (1.0,) * 6
    sensor_noise: bool = True
    duration: float | None = None
    signing_key: bytes | None = None
    truth_log: Path | None = None
    deny_arm: bool = False
    land_detector_fails: bool = False
    pilot_mode: tuple[str, float] | None = None
    silent_after: float | None = None
    weak_motor: tuple[int, float, float] | None = None
    hidden_effects: tuple[ModelEffect, ...] = ()
    lockstep: bool = False


@dataclass(frozen=True)
class SimSummary:
    """What a session did: timing, traffic and rejected signatures."""

    clock: ClockStats
    received: int
    sent: int
    setpoints_received: int
    setpoints_applied: int
    rejected: dict[str, Any] = field(default_factory=dict)
    truth_log: Path | None = None

    def line(self) -> str:
        """One line for the console."""
        c, r = self.clock, self.rejected
        lockstep = (f", lock-step {c.lockstep_frames} frames, {c.lockstep_timeouts} "
                    "timeouts" if c.lockstep_frames or c.lockstep_timeouts else "")
        text = (f"stopped after {c.sim_time:.3f} s sim time ({c.wall_time:.2f} s wall, "
                f"{c.mean_tick_rate:.1f} Hz control, max tick lag {1000 * c.max_lag:.1f} ms"
                f"{lockstep}); "
                f"{self.received} messages in, {self.sent} out, "
                f"{self.setpoints_received} setpoints; rejected signatures {r['total']} "
                f"({r['unsigned']} unsigned, {r['bad_signature']} bad; {r['commands']} "
                f"commands, {r['setpoints']} setpoints)")
        if self.truth_log is not None:
            text += f"; truth log {self.truth_log}"
        return text
