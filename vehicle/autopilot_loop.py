"""The flight an autopilot flies from streamed setpoints: a model of its closed loop.

`AutopilotLoop` is an autopilot's loop set from its parameters (the autopilot's own names
and units, each absent one at its stock default): ArduCopter's position and attitude
controllers with their input shaping (`mavsysid.vehicle.arducopter_loop`) or PX4's
offboard position control and attitude control (`mavsysid.vehicle.px4_loop`). `fly`
streams a trajectory to it as the streamer does (position, velocity, acceleration, yaw and
yaw rate at the setpoint rate, `mavsysid.flight.ground.setpoints`) and returns the
predicted flown flight (`FlownFlight`): position, attitude, body rates and rotor speeds as
the paper's model needs them to produce that motion (thrust and J ω̇ + ω × J ω through
the allocation A⁺ at the given θ).

The planner plans on this flight instead of the setpoints (`PlannerSettings.autopilot`);
``bench/autopilot_prediction.py`` checks it against ArduCopter SITL and `mavsysid sim`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from mavsysid.vehicle import arducopter_loop, px4_loop
from mavsysid.vehicle.allocation import allocation_matrix, allocation_pinv
from mavsysid.vehicle.config_types import VehicleConfig
from mavsysid.vehicle.dynamics import ATT, POS, RATE, STATE_DIM, VEL
from mavsysid.vehicle.rotation import continuous_sign, quat_to_matrix, quat_yaw
from mavsysid.vehicle.trajectory import Trajectory

__all__ = [
    "ARDUCOPTER_LOOP_DEFAULTS",
    "PX4_LOOP_DEFAULTS",
    "AutopilotLoop",
    "FlownFlight",
    "flown_flight",
    "fly",
    "fly_setpoints",
    "loop_parameter_names",
    "setpoint_rows",
    "torque_per_output",
    "yaw_damping",
]

#: ArduCopter's loop parameters and their stock defaults (own units: cm, cdeg, deg, Hz),
#: ArduPilot 90700977 (AC_PosControl, AC_AttitudeControl(_Multi), AC_WPNav, AP_Motors).
ARDUCOPTER_LOOP_DEFAULTS: dict[str, float] = {
    "SCHED_LOOP_RATE": 400.0, "MOT_THST_HOVER": 0.35,
    "WPNAV_SPEED": 1000.0, "WPNAV_SPEED_UP": 250.0, "WPNAV_SPEED_DN": 150.0,
    "WPNAV_ACCEL": 250.0, "WPNAV_ACCEL_Z": 100.0, "PSC_JERK_XY": 5.0, "PSC_JERK_Z": 5.0,
    "ANGLE_MAX": 3000.0, "PSC_ANGLE_MAX": 0.0,
    "PSC_POSXY_P": 1.0, "PSC_VELXY_P": 2.0, "PSC_VELXY_I": 1.0, "PSC_VELXY_D": 0.25,
    "PSC_VELXY_IMAX": 1000.0, "PSC_VELXY_FLTE": 5.0, "PSC_VELXY_FLTD": 5.0,
    "PSC_VELXY_FF": 0.0, "PSC_POSZ_P": 1.0, "PSC_VELZ_P": 5.0, "PSC_VELZ_I": 0.0,
    "PSC_VELZ_FLTE": 5.0, "PSC_ACCZ_P": 0.5, "PSC_ACCZ_I": 1.0, "PSC_ACCZ_IMAX": 800.0,
    "PSC_ACCZ_FLTE": 20.0,
    "ATC_INPUT_TC": 0.15, "ATC_ACCEL_R_MAX": 110000.0, "ATC_ACCEL_P_MAX": 110000.0,
    "ATC_ACCEL_Y_MAX": 27000.0, "ATC_RATE_R_MAX": 0.0, "ATC_RATE_P_MAX": 0.0,
    "ATC_RATE_Y_MAX": 0.0, "ATC_SLEW_YAW": 6000.0, "ATC_RATE_FF_ENAB": 1.0,
    "ATC_ANG_RLL_P": 4.5, "ATC_ANG_PIT_P": 4.5, "ATC_ANG_YAW_P": 4.5,
    **{f"ATC_RAT_{axis}_{name}": value for axis in ("RLL", "PIT") for name, value in (
        ("P", 0.135), ("I", 0.135), ("D", 0.0036), ("FF", 0.0), ("IMAX", 0.5),
        ("FLTT", 20.0), ("FLTE", 0.0), ("FLTD", 20.0))},
    **{f"ATC_RAT_YAW_{name}": value for name, value in (
        ("P", 0.18), ("I", 0.018), ("D", 0.0), ("FF", 0.0), ("IMAX", 0.5), ("FLTT", 20.0),
        ("FLTE", 2.5), ("FLTD", 20.0))},
}

#: PX4's offboard loop parameters and their defaults (own units: m, deg, deg/s), PX4
#: v1.15 parameter reference (mc_pos_control, mc_att_control, mc_rate_control).
PX4_LOOP_DEFAULTS: dict[str, float] = {
    "MPC_XY_P": 0.95, "MPC_Z_P": 1.0, "MPC_XY_VEL_P_ACC": 1.8, "MPC_XY_VEL_I_ACC": 0.4,
    "MPC_XY_VEL_D_ACC": 0.2, "MPC_Z_VEL_P_ACC": 4.0, "MPC_Z_VEL_I_ACC": 2.0,
    "MPC_Z_VEL_D_ACC": 0.0, "MPC_XY_VEL_MAX": 12.0, "MPC_Z_VEL_MAX_UP": 3.0,
    "MPC_Z_VEL_MAX_DN": 1.5, "MPC_TILTMAX_AIR": 45.0, "MPC_THR_HOVER": 0.5,
    "MC_ROLL_P": 6.5, "MC_PITCH_P": 6.5, "MC_YAW_P": 2.8, "MC_YAW_WEIGHT": 0.4,
    "MC_ROLLRATE_MAX": 220.0, "MC_PITCHRATE_MAX": 220.0, "MC_YAWRATE_MAX": 200.0,
    "MC_ROLLRATE_P": 0.15, "MC_ROLLRATE_I": 0.2, "MC_ROLLRATE_D": 0.003, "MC_ROLLRATE_K": 1.0,
    "MC_PITCHRATE_P": 0.15, "MC_PITCHRATE_I": 0.2, "MC_PITCHRATE_D": 0.003,
    "MC_PITCHRATE_K": 1.0, "MC_YAWRATE_P": 0.2, "MC_YAWRATE_I": 0.1, "MC_YAWRATE_D": 0.0,
    "MC_YAWRATE_K": 1.0, "IMU_DGYRO_CUTOFF": 30.0,
}

_DEFAULTS = {"ardupilot": ARDUCOPTER_LOOP_DEFAULTS, "px4": PX4_LOOP_DEFAULTS}
_KERNELS = {"ardupilot": arducopter_loop, "px4": px4_loop}


def loop_parameter_names(autopilot: str) -> list[str]:
    """The parameters an autopilot's loop is set from.

    Parameters
    ----------
    autopilot : str
        "ardupilot" or "px4".
    """
    return list(_DEFAULTS[autopilot])


def torque_per_output(config: VehicleConfig, theta: np.ndarray | None = None) -> np.ndarray:
    """Roll, pitch and yaw torque (N·m) of one unit of a rate controller's output, (3,).

    The motor mixer of ArduPilot (and PX4's, roughly) adds to each motor's thrust share
    the axis' factor times the output, the factors scaled to ±0.5 at most; a motor's
    thrust share of 1 is c_T n_max². The torque per unit is then Σ_i f_i a_i T_max with
    a_i the torque per newton of motor i (the allocation A over c_T).

    Parameters
    ----------
    config : VehicleConfig
        Rotor layout and ``rotor_speed_max``.
    theta : ndarray, shape (6,), optional
        θ, SI (default: the nominal).
    """
    theta = config.theta if theta is None else np.asarray(theta, dtype=float)
    arms = allocation_matrix(config, theta)[1:] / theta[0]
    thrust_max = theta[0] * config.limits.rotor_speed_max**2
    factors = 0.5 * arms / np.max(np.abs(arms), axis=1, keepdims=True)
    return np.sum(factors * arms, axis=1) * thrust_max


def yaw_damping(config: VehicleConfig, theta: np.ndarray | None = None) -> float:
    """The yaw-rate damping of the rotor drag per unit thrust acceleration T/m, s/m.

    The paper's rotor drag −T_i c_D v_i at each rotor's own velocity ω × r_i: with the
    thrust shared equally, ω̇_z = −(m c_D Σ_i |r_i,xy|² / (k j_z)) (T/m) ω_z.

    Parameters
    ----------
    config : VehicleConfig
        Mass and rotor layout.
    theta : ndarray, shape (6,), optional
        θ, SI (default: the nominal).
    """
    theta = config.theta if theta is None else np.asarray(theta, dtype=float)
    r = config.rotor_positions
    return float(config.mass * theta[1] * np.sum(r[:, 0]**2 + r[:, 1]**2)
                 / (r.shape[0] * theta[5]))


@dataclass(frozen=True)
class AutopilotLoop:
    """An autopilot's closed loop, set from its parameters.

    Attributes
    ----------
    autopilot : str
        "ardupilot" (ArduCopter GUIDED) or "px4" (PX4 OFFBOARD).
    parameters : tuple of (str, float)
        Every loop parameter (`loop_parameter_names`) in the autopilot's own units: the
        values read from the vehicle, the stock default for any it did not report.
    setpoint_rate : float
        The streamer's setpoint rate, Hz.
    """

    autopilot: str
    parameters: tuple[tuple[str, float], ...]
    setpoint_rate: float = 50.0

    @classmethod
    def from_parameters(cls, autopilot: str, values: Mapping[str, float] | None = None,
                        setpoint_rate: float = 50.0) -> AutopilotLoop:
        """The loop of an autopilot, its parameters over their defaults.

        Parameters
        ----------
        autopilot : str
            "ardupilot" or "px4".
        values : mapping, optional
            Parameter name → value in its own unit; names that are not loop parameters are
            ignored.
        setpoint_rate : float
            The streamer's setpoint rate, Hz.
        """
        defaults = _DEFAULTS[autopilot]
        merged = {name: float((values or {}).get(name, default))
                  for name, default in defaults.items()}
        return cls(autopilot, tuple(sorted(merged.items())), float(setpoint_rate))

    def value(self, name: str) -> float:
        """One parameter, in the autopilot's own unit.

        Parameters
        ----------
        name : str
            A loop parameter (`loop_parameter_names`).
        """
        return dict(self.parameters)[name]

    @cached_property
    def loop_rate(self) -> float:
        """The rate its controllers run at, Hz."""
        return self.value("SCHED_LOOP_RATE") if self.autopilot == "ardupilot" else 400.0

    @cached_property
    def hover_throttle(self) -> float:
        """The throttle (thrust share) that holds the vehicle's weight."""
        return self.value("MOT_THST_HOVER" if self.autopilot == "ardupilot"
                          else "MPC_THR_HOVER")

    def kernel_parameters(self, config: VehicleConfig, dt: float,
                          theta: np.ndarray | None = None) -> np.ndarray:
        """The loop's parameter vector in SI (the kernel's layout).

        Parameters
        ----------
        config : VehicleConfig
            The vehicle (its torque per rate-controller output and yaw damping).
        dt : float
            Tick, s.
        theta : ndarray, shape (6,), optional
            θ, SI (default: the nominal).
        """
        theta = config.theta if theta is None else np.asarray(theta, dtype=float)
        plant = torque_per_output(config, theta) / theta[3:6]
        return _KERNELS[self.autopilot].kernel_parameters(
            dict(self.parameters), dt, plant, float(theta[1]), yaw_damping(config, theta))


@dataclass(frozen=True)
class FlownFlight:
    """The predicted flight, S samples (world ENU, body FLU, SI).

    Attributes
    ----------
    times : ndarray, shape (S,)
        s from the first setpoint.
    position, velocity, acceleration : ndarray, shape (S, 3)
    quaternion : ndarray, shape (S, 4)
        Body → world, sign-continuous.
    body_rates, angular_acceleration : ndarray, shape (S, 3)
        ω (rad/s) and ω̇ (rad/s²), body frame.
    thrust : ndarray, shape (S,)
        Collective thrust, N.
    torque : ndarray, shape (S, 3)
        The rotors' torque J ω̇_m + ω × J ω, N·m, ω̇_m the motors' share of ω̇ (ω̇ plus the
        rotor drag's yaw damping).
    rotor_speeds_squared : ndarray, shape (S, k)
        A⁺ [T, τ], (rad/s)²; negative where the wrench is beyond the rotors.
    desired_position : ndarray, shape (S, 3)
        The autopilot's shaped position target (ArduCopter; the setpoint for PX4).
    attitude_target : ndarray, shape (S, 4)
        The attitude controller's target.
    """

    times: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    quaternion: np.ndarray
    body_rates: np.ndarray
    angular_acceleration: np.ndarray
    thrust: np.ndarray
    torque: np.ndarray
    rotor_speeds_squared: np.ndarray
    desired_position: np.ndarray
    attitude_target: np.ndarray

    @property
    def rotor_speeds(self) -> np.ndarray:
        """Rotor speeds n, rad/s, shape (S, k) (n² clipped at zero first)."""
        return np.sqrt(np.clip(self.rotor_speeds_squared, 0.0, None))

    @property
    def yaw(self) -> np.ndarray:
        """Heading of the body x axis, rad (ENU, unwrapped), shape (S,)."""
        return np.unwrap(quat_yaw(self.quaternion))

    def states(self) -> np.ndarray:
        """Model states [p, v_B, q, ω], shape (S, 13)."""
        x = np.empty((self.times.size, STATE_DIM))
        x[:, POS] = self.position
        x[:, ATT] = self.quaternion
        x[:, VEL] = np.einsum("sji,sj->si", quat_to_matrix(self.quaternion), self.velocity)
        x[:, RATE] = self.body_rates
        return x


def setpoint_rows(trajectory: Trajectory, rate: float, duration: float | None = None,
                  start: float = 0.0) -> np.ndarray:
    """The streamer's setpoints of a trajectory: rows [t, p (3), v (3), a (3), yaw, yaw
    rate], shape (M, 12), t in s from ``start``.

    Parameters
    ----------
    trajectory : Trajectory
    rate : float
        Setpoint rate, Hz.
    duration : float, optional
        How long, s (default: to the trajectory's end).
    start : float
        Trajectory time of the first setpoint, s.
    """
    span = trajectory.duration - start if duration is None else duration
    times = np.arange(0.0, span + 1e-9, 1.0 / rate)
    f = trajectory.flat_outputs(start + times)
    return np.column_stack([times, f.position, f.velocity, f.acceleration, f.yaw, f.yaw_rate])


def fly(loop: AutopilotLoop, trajectory: Trajectory, config: VehicleConfig,
        theta: np.ndarray | None = None, sample_step: float | None = None,
        duration: float | None = None, start: float = 0.0) -> FlownFlight:
    """Predict the flight ``loop`` flies when ``trajectory`` is streamed to it.

    The loop starts in steady flight on the trajectory at ``start`` (s of the
    trajectory) and receives its setpoints from then on at ``loop.setpoint_rate``
    (`setpoint_rows`, `fly_setpoints`).

    Parameters
    ----------
    loop : AutopilotLoop
    trajectory : Trajectory
        Flat outputs: position (m, ENU) and yaw (rad) over time.
    config : VehicleConfig
        Mass, rotors and limits; θ (default: its nominal) gives the inertia, the torque
        per rate-controller output and the allocation.
    theta : ndarray, shape (6,), optional
    sample_step : float, optional
        Step of the returned samples, s; it is cut into whole loop ticks of about
        1/``loop.loop_rate`` (default: one tick).
    duration : float, optional
        How long to fly, s (default: to the trajectory's end).
    start : float
        Trajectory time of the first setpoint, s.
    """
    span = trajectory.duration - start if duration is None else float(duration)
    rows = setpoint_rows(trajectory, loop.setpoint_rate, span, start)
    return fly_setpoints(loop, rows, config, theta, sample_step, span)


def fly_setpoints(loop: AutopilotLoop, rows: np.ndarray, config: VehicleConfig,
                  theta: np.ndarray | None = None, sample_step: float | None = None,
                  duration: float | None = None) -> FlownFlight:
    """Predict the flight ``loop`` flies from setpoints as they arrive.

    Parameters
    ----------
    loop : AutopilotLoop
    rows : ndarray, shape (M, 12)
        Setpoints [t, p (3), v (3), a (3), yaw, yaw rate] (s, m, m/s, m/s², rad, rad/s,
        world ENU) in the order they arrive, t from 0; the loop starts in steady flight on
        the first.
    config, theta, sample_step
        As for `fly`.
    duration : float, optional
        How long to fly, s (default: to the last setpoint).
    """
    theta = config.theta if theta is None else np.asarray(theta, dtype=float)
    span = float(rows[-1, 0]) if duration is None else float(duration)
    tick = 1.0 / loop.loop_rate
    step = tick if sample_step is None else float(sample_step)
    per_sample = max(1, round(step / tick))
    samples = max(1, round(span / step))
    kernel = _KERNELS[loop.autopilot]
    params = _kernel_parameters(loop, config, theta)
    params[0] = span / (samples * per_sample)  # the tick, P_DT of either kernel
    state = kernel.initial_state(rows[0, 1:4], rows[0, 4:7], rows[0, 7:10], float(rows[0, 10]),
                                 float(rows[0, 11]), loop.hover_throttle)
    out = np.empty((samples + 1, kernel.RECORD_COLUMNS))
    kernel.run_loop(params, np.ascontiguousarray(rows, dtype=float), state,
                    samples * per_sample, per_sample, out)
    return flown_flight(out, config, theta)


_PARAMETER_CACHE: dict[tuple, tuple[VehicleConfig, np.ndarray]] = {}


def _kernel_parameters(loop: AutopilotLoop, config: VehicleConfig, theta: np.ndarray
                       ) -> np.ndarray:
    """A copy of ``loop``'s kernel parameters for ``config`` at ``theta`` (kept: the
    planner flies thousands of segments through one loop)."""
    key = (loop, id(config), theta.tobytes())
    hit = _PARAMETER_CACHE.get(key)
    if hit is None or hit[0] is not config:
        if len(_PARAMETER_CACHE) >= 64:
            _PARAMETER_CACHE.clear()
        hit = (config, loop.kernel_parameters(config, 1.0 / loop.loop_rate, theta))
        _PARAMETER_CACHE[key] = hit
    return hit[1].copy()


def flown_flight(records: np.ndarray, config: VehicleConfig, theta: np.ndarray) -> FlownFlight:
    """`FlownFlight` of a kernel's recorded rows.

    Parameters
    ----------
    records : ndarray, shape (S, RECORD_COLUMNS)
        Rows of `mavsysid.vehicle.arducopter_loop.run_loop` (or ``px4_loop``'s).
    config : VehicleConfig
        Mass and allocation.
    theta : ndarray, shape (6,)
        θ, SI.
    """
    q = continuous_sign(records[:, 10:14])
    w, dw = records[:, 14:17], records[:, 17:20]
    J = theta[3:6]
    torque = J * records[:, 28:31] + np.cross(w, J * w)
    thrust = config.mass * records[:, 20]
    wrench = np.column_stack([thrust, torque])
    n2 = wrench @ allocation_pinv(config, theta).T
    return FlownFlight(
        times=records[:, 0].copy(), position=records[:, 1:4].copy(),
        velocity=records[:, 4:7].copy(), acceleration=records[:, 7:10].copy(),
        quaternion=q, body_rates=w.copy(), angular_acceleration=dw.copy(), thrust=thrust,
        torque=torque, rotor_speeds_squared=n2, desired_position=records[:, 21:24].copy(),
        attitude_target=records[:, 24:28].copy())

