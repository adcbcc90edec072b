"""The equation-error rows of a flight: the measured [f, ω̇] and the model's, through one smoother.

The *equation error* per sample and axis is

    r = [f_meas − F_B/m,  ω̇_meas − J⁻¹(M_B − ω × J ω)]       (paper Eqs. newton, euler)

with f_meas = Rᵀ(a − g) the body specific force (m/s²) and ω̇_meas the angular
acceleration (rad/s²), both from the smoothed pose (`mavsysid.estimation.signals`), and
F_B, M_B the model's wrench (paper Eq. drag, the kernels of `mavsysid.vehicle.mav_model`,
plus any `ModelEffect` wrench) at the smoothed states and the logged rotor speeds
(`model_accelerations`); the model goes through the same smoother
(`consistent_accelerations`) so that the smoother's attenuation applies to both sides.

`BalanceBuilder` writes the balance as linear regressions. Euler's equation solved per
axis,

    ω̇_x = (c_T/j_x) τ_x − ((j_z − j_y)/j_x) ω_y ω_z,   and cyclically,

is linear in the ratios of `TORQUE_COEFFICIENTS`; the force rows are linear in c_T and
c_T c_D (`FORCE_COEFFICIENTS`). The unit wrenches come from the model's own kernel at
θ = e_c_T, e_c_T + e_c_D and e_c_M, so no law is written twice. Terms beyond the paper's
model enter as nuisance coefficients so that they are not taken for inertia: the rotors'
angular momentum (J_r Σ ε_i ṅ_i about z and the precession −ω × h about x and y), the
rotor drag's yaw moment, and in the force rows a rotor drag linear in rotor speed (without
it the quadratic c_D absorbs the linear one). Each nuisance quantity of the vehicle
(`mavsysid.vehicle.parameters`) adds its term's columns after the model's. The thrust row
compares magnitudes: an attitude error shortens the measured z component by cos ε, which
the magnitude is free of.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from mavsysid.estimation.signals import (
    ImuSegment,
    SmoothedPose,
    SmootherSettings,
    UniformSegment,
    acceleration_kernel,
    body_force_readout,
    body_rotation_readout,
    convolve_columns,
    rate_kernel,
    savgol_kernel,
    smooth_pose,
)
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.effect_base import EffectInputs
from mavsysid.vehicle.imu import lever_arm_acceleration
from mavsysid.vehicle.mav_model import euler_acceleration, rotor_wrench
from mavsysid.vehicle.model_effects import ModelEffect, RotorDragLinear, total_wrench
from mavsysid.vehicle.parameters import INERTIA, QuantityTerm
from scipy.signal import butter, lfilter, lfilter_zi

__all__ = [
    "FORCE_COEFFICIENTS",
    "ROTOR_FORCE_COLUMNS",
    "ROTOR_TORQUE_COLUMNS",
    "STACKED_COEFFICIENTS",
    "TORQUE_AXIS",
    "TORQUE_COEFFICIENTS",
    "BalanceBuilder",
    "BalanceRows",
    "BandFilter",
    "ImuBalanceBuilder",
    "builder_for",
    "consistent_accelerations",
    "model_accelerations",
]


#: Coefficients of the force rows: c_T, c_T c_D and the nuisance ``drag_linear``, the
#: in-plane k of a rotor drag linear in rotor speed (N·s/(m·rad)).
FORCE_COEFFICIENTS = ("c_T", "c_T*c_D", "drag_linear")
#: Coefficients of the torque rows, in column order. ``g_*`` are the gyroscopic
#: coefficients −(j_z − j_y)/j_x, −(j_x − j_z)/j_y, −(j_y − j_x)/j_z; ``rotor_gyro_x`` is
#: −J_r/j_x on Σε_i n_i ω_y, ``rotor_gyro_y`` is J_r/j_y on Σε_i n_i ω_x; ``drag_z`` is
#: c_T c_D / j_z (the rotor drag's yaw moment); ``rotor_inertia_z`` is −J_r / j_z on
#: Σ ε_i ṅ_i.
TORQUE_COEFFICIENTS = ("c_T/j_x", "g_x", "rotor_gyro_x", "c_T/j_y", "g_y", "rotor_gyro_y",
                       "c_M/j_z", "drag_z", "g_z", "rotor_inertia_z")
#: Which torque axis each torque coefficient's column acts on (0 = x, 1 = y, 2 = z).
TORQUE_AXIS = (0, 0, 0, 1, 1, 1, 2, 2, 2, 2)
#: Columns of the torque rows that depend on the rotor speeds (the rest on the pose only).
ROTOR_TORQUE_COLUMNS = (0, 2, 3, 5, 6, 7, 9)
#: Columns of the force rows that depend on the rotor speeds.
ROTOR_FORCE_COLUMNS = (0, 1, 2)
#: All coefficients, force then torque: the stacked vector of `parameter_status`.
STACKED_COEFFICIENTS = FORCE_COEFFICIENTS + TORQUE_COEFFICIENTS


@dataclass(frozen=True)
class BalanceRows:
    """The measured side and the model columns of one segment (N rows, smoother edges cut).

    Attributes
    ----------
    t : ndarray, shape (N,)
        s.
    force : ndarray, shape (N, 3)
        Measured body specific force, m/s².
    force_columns : ndarray, shape (N, 3, 3 + E)
        Model body specific force per unit of each `FORCE_COEFFICIENTS` entry, then of
        each of the config's E nuisance quantities.
    torque : ndarray, shape (N, 3)
        Measured body angular acceleration minus the model's rate term, rad/s².
    torque_columns : ndarray, shape (N, 3, 10 + E)
        Model angular acceleration per unit of each `TORQUE_COEFFICIENTS` entry, then of
        each nuisance quantity.
    """

    t: np.ndarray
    force: np.ndarray
    force_columns: np.ndarray
    torque: np.ndarray
    torque_columns: np.ndarray

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def rows(self, keep: np.ndarray | slice) -> BalanceRows:
        """A subset of the rows."""
        return BalanceRows(self.t[keep], self.force[keep], self.force_columns[keep],
                           self.torque[keep], self.torque_columns[keep])


class BandFilter(Protocol):
    """A zero-phase linear filter along time (axis 0), and how long its edges settle."""

    def apply(self, x: np.ndarray, dt: float) -> np.ndarray:
        """``x`` filtered along axis 0, same shape."""

    def settle(self) -> float:
        """Time to cut off each end after filtering, s."""


def _unit_wrenches(n: np.ndarray, config: VehicleConfig, v_b: np.ndarray, w: np.ndarray
                   ) -> tuple[np.ndarray, ...]:
    """Body force and torque per unit c_T, per unit c_T c_D (drag) and per unit c_M."""
    r, eps = config.rotor_positions, config.rotor_directions
    e = np.eye(6)
    f_t, m_t = rotor_wrench(n, e[0], r, eps, v_b, w)
    f_td, m_td = rotor_wrench(n, e[0] + e[1], r, eps, v_b, w)
    _, m_m = rotor_wrench(n, e[2], r, eps, v_b, w)
    return f_t, f_td - f_t, m_t, m_td - m_t, m_m


def _linear_drag_force(n: np.ndarray, config: VehicleConfig, inputs: EffectInputs
                       ) -> np.ndarray:
    """Body force of the catalogue's linear rotor drag per unit in-plane k (k_z = 0), N."""
    force, _ = RotorDragLinear(k=1.0, k_z=0.0).wrench(inputs)
    return force


def _thrust_row_as_magnitude(force: np.ndarray, cols: np.ndarray, c_d: float,
                             drag_linear: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The z row replaced by magnitudes: |f| against |thrust + drag| per unit c_T.

    An attitude error ε turns the measured specific force out of z_B and shortens its z
    component by cos ε ≈ 1 − ε²/2: with a noisy attitude (an on-board estimator's, 1°) the
    z row alone would bias c_T low by σ_ε². The magnitude is free of it. The rotor drag,
    perpendicular to the thrust, lengthens it at second order, so the model's magnitude
    includes it: c_D times the quadratic column and ``drag_linear`` (k / c_T) times the
    linear one (linear in c_T; the drag columns leave this row). A nuisance quantity's
    column enters the magnitude along the thrust (its first-order change of it).
    """
    force, cols = force.copy(), cols.copy()
    force[:, 2] = np.linalg.norm(force, axis=1)
    drag = c_d * cols[:, :, 1] + drag_linear * cols[:, :, 2]
    thrust = cols[:, :, 0] + drag
    magnitude = np.linalg.norm(thrust, axis=1)
    along = thrust / np.where(magnitude > 0.0, magnitude, 1.0)[:, None]
    extras = np.einsum("na,nae->ne", along, cols[:, :, len(FORCE_COEFFICIENTS):])
    cols[:, 2, 0] = magnitude
    cols[:, 2, 1:] = 0.0
    cols[:, 2, len(FORCE_COEFFICIENTS):] = extras
    return force, cols


class BalanceBuilder:
    """Builds `BalanceRows` of one segment for any delay, smoothing the pose once.

    Both sides come from the pose: the specific force and the angular acceleration its
    second derivatives give, and the model's columns through the same smoother
    (`body_force_readout`, `body_rotation_readout`).

    Parameters
    ----------
    segment : UniformSegment
        Fresh pose on a uniform grid, and the rotor speeds.
    config : VehicleConfig
        Mass, rotor positions and spin directions.
    window : float
        Savitzky–Golay window (cubic), s.
    """

    def __init__(self, segment: UniformSegment, config: VehicleConfig, window: float
                 ) -> None:
        self.segment, self.config, self.dt = segment, config, segment.dt
        self.settings = SmootherSettings(window=window, polyorder=3)
        self.pose = smooth_pose(segment.t, segment.position, segment.quaternion,
                                self.settings, "flight segment")
        self.kernel = acceleration_kernel(self.settings, self.dt)
        self.rates = self.pose.rates
        self.velocity_body = self.pose.velocity_body()
        self._rate_term = body_rotation_readout(self.pose, self.pose,
                                                np.zeros_like(self.rates), self.kernel)
        self._gyroscopic = self._gyroscopic_columns()

    def _gyroscopic_columns(self) -> dict[int, np.ndarray]:
        w = self.rates
        products = np.column_stack([w[:, 1] * w[:, 2], w[:, 2] * w[:, 0], w[:, 0] * w[:, 1]])
        return {col: self._readout(axis, products[:, axis])
                for col, axis in ((1, 0), (4, 1), (8, 2))}

    def _readout(self, axis: int, values: np.ndarray) -> np.ndarray:
        """An angular acceleration about ``axis`` as the measured side sees it, (N, 3)."""
        omega_dot = np.zeros((len(values), 3))
        omega_dot[:, axis] = values
        return self._rotation_readout(omega_dot)

    def _rotation_readout(self, omega_dot: np.ndarray) -> np.ndarray:
        return body_rotation_readout(self.pose, self.pose, omega_dot, self.kernel,
                                     rate_term=False)

    def _force_readout(self, force: np.ndarray) -> np.ndarray:
        """A body specific force (N, 3) as the measured side sees it."""
        return body_force_readout(self.pose, self.pose, force, self.kernel)

    def measured(self) -> tuple[np.ndarray, np.ndarray]:
        """The measured side: specific force and angular acceleration less the rate term."""
        return self.pose.specific_force(), self.pose.angular_acceleration - self._rate_term

    def _inputs(self, n: np.ndarray) -> EffectInputs:
        pose = self.pose
        return EffectInputs(pose.t - self.segment.flight_start, pose.position, pose.quaternion,
                            self.velocity_body, self.rates, n, self.config.theta,
                            self.config.rotor_positions,
                            rotor_directions=self.config.rotor_directions,
                            angular_acceleration=pose.angular_acceleration)

    def _extra_columns(self, n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each nuisance quantity's columns per unit value: force (N, 3, E), torque (N, 3, E).

        Its term (`mavsysid.vehicle.parameters.QuantityTerm`) at the smoothed states, through
        the same readouts as the model's: a wrench's force per unit mass and torque over the
        prior's inertia (the rows are angular accelerations, so the coefficient is the
        quantity's value to the ratio of the prior's inertia to the true one); what an
        accelerometer reads, in the force rows where the measured side is an accelerometer.
        """
        config = self.config
        inputs = self._inputs(n)
        inertia = config.theta[INERTIA]
        forces, torques = [], []
        for quantity in config.extra_quantities:
            assert quantity.term is not None
            force, torque = quantity.term.wrench_basis(inputs)
            force = force / config.mass + self._reading_force(quantity.term, inputs)
            forces.append(self._force_readout(force))
            torques.append(self._rotation_readout(torque / inertia))
        return np.stack(forces, axis=-1), np.stack(torques, axis=-1)

    def _reading_force(self, term: QuantityTerm, inputs: EffectInputs) -> np.ndarray:
        """What a sensor term adds to the measured specific force (none from a pose)."""
        return np.zeros((inputs.t.shape[0], 3))

    @property
    def edge(self) -> int:
        """Samples at each end where the smoother is one-sided."""
        return self.settings.samples(self.dt)

    def _columns(self, n: np.ndarray, c_d: float) -> tuple[np.ndarray, np.ndarray]:
        """The model's force (N, 3, 3 + E) and torque (N, 3, 10 + E) columns at speeds n."""
        n_dot = np.gradient(n, self.dt, axis=0)
        config, v_b, w = self.config, self.velocity_body, self.rates
        f_t, f_d, m_t, m_d, m_m = _unit_wrenches(n, config, v_b, w)
        f_l = _linear_drag_force(n, config, self._inputs(n))
        force_cols = np.stack([self._force_readout(f / config.mass) for f in (f_t, f_d, f_l)],
                              axis=-1)
        thrust_torque = m_t + c_d * m_d
        spin = n @ config.rotor_directions
        rotor_cols = {0: (0, thrust_torque[:, 0]), 2: (0, spin * w[:, 1]),
                      3: (1, thrust_torque[:, 1]), 5: (1, spin * w[:, 0]),
                      6: (2, m_m[:, 2]), 7: (2, m_d[:, 2]),
                      9: (2, n_dot @ config.rotor_directions)}
        torque_cols = np.empty((len(n), 3, len(TORQUE_COEFFICIENTS)))
        for col, (axis, values) in rotor_cols.items():
            torque_cols[:, :, col] = self._readout(axis, values)
        for col, readout in self._gyroscopic.items():
            torque_cols[:, :, col] = readout
        if config.extra_quantities:
            extra_force, extra_torque = self._extra_columns(n)
            force_cols = np.concatenate([force_cols, extra_force], axis=-1)
            torque_cols = np.concatenate([torque_cols, extra_torque], axis=-1)
        return force_cols, torque_cols

    def rows(self, delay: float, c_d: float, roll_pitch: BandFilter | None = None,
             yaw: BandFilter | None = None, force: BandFilter | None = None,
             trim: float = 0.0, magnitude: bool = True, drag_linear: float = 0.0,
             drag_c_d: float = float("nan")) -> BalanceRows:
        """The balance rows at ``delay`` (module docstring).

        Parameters
        ----------
        delay : float
            The measured side lags the rotor speeds by this much, s.
        c_d : float
            c_D used to add the rotor drag's roll and pitch moment to the thrust torque,
            s/m (zero when the rotors lie in the plane of the centre of gravity).
        roll_pitch, yaw, force : BandFilter, optional
            Applied to both sides of the ω̇_x, ω̇_y rows, the ω̇_z rows and the force rows.
        trim : float
            Time cut off each end, s, beyond the smoother's and the filters' edges.
        magnitude : bool
            Make the thrust row the specific force's magnitude (else its z component; an
            accelerometer's z row needs no magnitude, and never gets one).
        drag_linear, drag_c_d : float
            k / c_T of the linear rotor drag (s·rad/m) and c_D (s/m, NaN: ``c_d``) in the
            thrust row's magnitude.
        """
        n = self.segment.rotor_speeds(delay)
        force_cols, torque_cols = self._columns(n, c_d)
        specific_force, torque = self.measured()
        settle = trim
        if force is not None:
            specific_force = force.apply(specific_force, self.dt)
            force_cols = force.apply(force_cols, self.dt)
            settle = max(settle, trim + force.settle())
        if magnitude and self.magnitude_row:
            specific_force, force_cols = _thrust_row_as_magnitude(specific_force, force_cols,
                c_d if np.isnan(drag_c_d) else drag_c_d, drag_linear)
        for band, axes in ((roll_pitch, [0, 1]), (yaw, [2])):
            if band is not None:
                torque[:, axes] = band.apply(torque[:, axes], self.dt)
                torque_cols[:, axes] = band.apply(torque_cols[:, axes], self.dt)
                settle = max(settle, trim + band.settle())
        edge = max(self.edge, int(np.ceil(settle / self.dt)))
        rows = BalanceRows(self.segment.t, specific_force, force_cols, torque, torque_cols)
        return rows.rows(slice(edge, max(edge, len(n) - edge)))

    #: Whether the thrust row compares magnitudes (a pose's attitude error shortens the
    #: z component of its specific force).
    magnitude_row = True


@dataclass(frozen=True)
class SensorFilter:
    """The low-pass an autopilot applies to its IMU before logging: second-order
    Butterworth at the cutoff (ArduPilot's ``INS_GYRO_FILTER``/``INS_ACCEL_FILTER``, PX4's
    ``IMU_GYRO_CUTOFF``/``IMU_ACCEL_CUTOFF``), discretised by the bilinear transform.

    The model's side of an IMU balance goes through it too, so that its gain and its lag
    (≈ 0.225 / f_c s at low frequency) apply to both sides and cancel.

    Attributes
    ----------
    b, a : ndarray, shape (3,)
        The biquad's coefficients.
    """

    b: np.ndarray
    a: np.ndarray

    @staticmethod
    def of(cutoff_hz: float | None, dt: float) -> SensorFilter | None:
        """The filter at ``cutoff_hz`` on samples ``dt`` s apart (None: none, or a cutoff
        at or above the Nyquist frequency)."""
        if cutoff_hz is None or not 0.0 < cutoff_hz < 0.5 / dt:
            return None
        b, a = butter(2, cutoff_hz, fs=1.0 / dt)
        return SensorFilter(b, a)

    @staticmethod
    def apply(sensor: SensorFilter | None, x: np.ndarray) -> np.ndarray:
        """``x`` (N, ...) filtered along time from rest at its first sample (None: as is)."""
        if sensor is None:
            return x
        zi = lfilter_zi(sensor.b, sensor.a).reshape((-1,) + (1,) * (x.ndim - 1))
        out, _ = lfilter(sensor.b, sensor.a, x, axis=0, zi=zi * x[:1])
        return np.asarray(out, float)


class ImuBalanceBuilder(BalanceBuilder):
    """Builds `BalanceRows` of one segment from the IMU, for any delay.

    The accelerometer is the specific force itself, in the body frame, and the gyro's
    first derivative the angular acceleration: no second derivative of the pose, no
    rotation between frames. Both sides go through one smoother: the accelerometer and the
    model's forces through the Savitzky–Golay smoother, the gyro through its derivative
    and the model's angular accelerations through that derivative's action on a rate
    (`mavsysid.estimation.signals.rate_kernel`). An IMU off the centre of gravity reads
    ω̇ × p + ω × (ω × p) more: taken off where p is stated, else a nuisance quantity's
    columns (`mavsysid.vehicle.imu.ImuOffset`); accelerometer biases likewise. The pose
    gives only the velocity the rotor drag needs.

    Parameters
    ----------
    segment : ImuSegment
        The IMU on a uniform grid, the pose's velocity on it, and the rotor speeds.
    config : VehicleConfig
        Mass, rotor positions and spin directions.
    window : float
        Savitzky–Golay window (cubic), s.
    """

    magnitude_row = False

    def __init__(self, segment: ImuSegment, config: VehicleConfig, window: float) -> None:
        self.segment, self.config, self.dt = segment, config, segment.dt
        self.settings = SmootherSettings(window=window, polyorder=3)
        self._gyro_filter = SensorFilter.of(segment.gyro_cutoff_hz, self.dt)
        self._accel_filter = SensorFilter.of(segment.accel_cutoff_hz, self.dt)
        samples = self.settings.samples(self.dt)
        self.smoother = savgol_kernel(samples, 3, 0, self.dt)
        self.kernel = rate_kernel(self.settings, self.dt)
        self.rates = convolve_columns(segment.gyro, self.smoother)
        self.angular_acceleration = convolve_columns(
            segment.gyro, savgol_kernel(samples, 3, 1, self.dt))
        self.velocity_body = segment.velocity_body
        self._gyroscopic = self._gyroscopic_columns()
        self.pose: SmoothedPose | None = None
        if segment.pose_position is not None and segment.pose_quaternion is not None:
            self.pose = smooth_pose(segment.t, segment.pose_position, segment.pose_quaternion,
                                    self.settings, "flight segment")
            self.force_kernel = acceleration_kernel(self.settings, self.dt)
            self.magnitude_row = True

    def _rotation_readout(self, omega_dot: np.ndarray) -> np.ndarray:
        return SensorFilter.apply(self._gyro_filter, convolve_columns(omega_dot, self.kernel))

    def _force_readout(self, force: np.ndarray) -> np.ndarray:
        if self.pose is not None:
            return body_force_readout(self.pose, self.pose, force, self.force_kernel)
        return SensorFilter.apply(self._accel_filter, convolve_columns(force, self.smoother))

    def measured(self) -> tuple[np.ndarray, np.ndarray]:
        """The specific force (the pose's, or the accelerometer's less its lever arm where
        stated) and the gyro's derivative."""
        if self.pose is not None:
            return self.pose.specific_force(), self.angular_acceleration.copy()
        force = convolve_columns(self.segment.accel, self.smoother)
        if self.segment.imu_position is not None:
            force = force - lever_arm_acceleration(self.rates, self.angular_acceleration,
                                                   self.segment.imu_position)
        return force, self.angular_acceleration.copy()

    def _inputs(self, n: np.ndarray) -> EffectInputs:
        s = self.segment
        return EffectInputs(s.t - s.flight_start, s.position, s.quaternion,
                            self.velocity_body, self.rates, n, self.config.theta,
                            self.config.rotor_positions,
                            rotor_directions=self.config.rotor_directions,
                            angular_acceleration=self.angular_acceleration)

    def _reading_force(self, term: QuantityTerm, inputs: EffectInputs) -> np.ndarray:
        if term.channel != "accel" or self.pose is not None:
            return np.zeros((inputs.t.shape[0], 3))
        return term.reading_basis(inputs)


def builder_for(segment: UniformSegment | ImuSegment, config: VehicleConfig, window: float
                ) -> BalanceBuilder:
    """The balance builder of a segment: from the IMU when it is an `ImuSegment`.

    Parameters
    ----------
    segment : UniformSegment or ImuSegment
    config : VehicleConfig
    window : float
        Savitzky–Golay window, s.
    """
    if isinstance(segment, ImuSegment):
        return ImuBalanceBuilder(segment, config, window)
    return BalanceBuilder(segment, config, window)


def model_accelerations(pose: SmoothedPose, rotor_speeds: np.ndarray, theta: np.ndarray,
                        config: VehicleConfig, effects: Sequence[ModelEffect] = ()
                        ) -> np.ndarray:
    """The model's [F_B/m, ω̇] at the smoothed states and given rotor speeds, shape (N, 6).

    Parameters
    ----------
    pose : SmoothedPose
    rotor_speeds : ndarray, shape (N, k)
        Speeds acting on the body, rad/s.
    theta : ndarray, shape (6,)
    config : VehicleConfig
        Mass and rotor geometry.
    effects : sequence of ModelEffect
        Effects whose wrench is added (paper F_ext, M_ext).
    """
    theta = np.asarray(theta, float)
    r = config.rotor_positions
    v_b = pose.velocity_body()
    w = pose.rates
    # Paper Eq. drag and the rotor moments, summed (the kernel the dynamics use).
    force, torque = rotor_wrench(rotor_speeds, theta, r, config.rotor_directions, v_b, w)
    if effects:
        inputs = EffectInputs(pose.t, pose.position, pose.quaternion, v_b, w, rotor_speeds,
                              theta, r, rotor_directions=config.rotor_directions)
        f_e, m_e = total_wrench(list(effects), inputs)
        force = force + f_e
        torque = torque + m_e
    # Paper Eq. euler: ω̇ = J⁻¹ (M_B − ω × J ω).
    omega_dot = euler_acceleration(torque, w, theta[3:6])
    return np.hstack([force / config.mass, omega_dot])


def consistent_accelerations(pose: SmoothedPose, inputs: SmoothedPose, model: np.ndarray,
                             settings: SmootherSettings, dt: float
                             ) -> tuple[np.ndarray, np.ndarray]:
    """Measured and model [f_B, ω̇] that went through the same (linear) smoother.

    Smoothing does not commute with the rotation to the body frame, so the comparison is
    made where the smoother acted: world acceleration a − g for the force (model: R F_B/m,
    paper Eq. newton in the world frame), and the quaternion's second derivative for the
    rotation (model: q̈ = q ⊗ (½[0, ω̇] − ¼‖ω‖² [1, 0]), from q̇ = ½ q ⊗ [0, ω]). The model's
    side is filtered by `acceleration_kernel`; both are then read in the smoothed body
    frame: f = Rᵀ(a − g), ω̇ = 2 Im(q* ⊗ q̈) (`body_force_readout`,
    `body_rotation_readout`).

    Parameters
    ----------
    pose : SmoothedPose
        The log smoothed with ``settings`` (the measured side).
    inputs : SmoothedPose
        The log smoothed with the light input window (the model's states).
    model : ndarray, shape (N, 6)
        `model_accelerations` at ``inputs``.
    settings : SmootherSettings
    dt : float
        Sample time, s.

    Returns
    -------
    measured, model : ndarray, shape (N, 6)
    """
    kernel = acceleration_kernel(settings, dt)
    measured = np.hstack([pose.specific_force(), pose.angular_acceleration])
    model_b = np.hstack([body_force_readout(pose, inputs, model[:, :3], kernel),
                         body_rotation_readout(pose, inputs, model[:, 3:], kernel)])
    return measured, model_b
