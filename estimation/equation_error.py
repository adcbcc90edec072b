"""The equation-error view of a flight: poses smoothed into accelerations, and the model's.

The *equation error* of a flight, per sample and axis, is

    r = [f_meas − F_B/m,  ω̇_meas − J⁻¹(M_B − ω × J ω)]       (paper Eqs. newton, euler)

with f_meas = Rᵀ(a − g) the body-frame specific force (m/s²) and ω̇_meas the angular
acceleration (rad/s²), both derived from the pose log by a Savitzky–Golay smoother
(`smooth_pose`), and F_B, M_B the model's wrench (paper Eq. drag, the kernels of
`mavsysid.vehicle.mav_model`, plus optional `ModelEffect` wrenches) at the smoothed state
and the logged rotor speeds (`model_accelerations`). The model prediction goes through
the same smoother (`consistent_accelerations`) so that the smoother's attenuation of
fast content applies to both sides and cancels.

The estimator fits θ to it (`mavsysid.estimation.equation_error_fit`) as a start and an
independent check of the filter; the diagnosis (`mavsysid.discrepancy.residuals`) adds
model effects to it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np
from mavsysid.vehicle.config import GRAVITY, VehicleConfig
from mavsysid.vehicle.mav_model import euler_acceleration, rotor_wrench
from mavsysid.vehicle.model_effects import EffectInputs, ModelEffect, total_wrench
from mavsysid.vehicle.rotation import continuous_sign, quat_multiply, quat_to_matrix
from scipy.ndimage import convolve1d
from scipy.signal import oaconvolve, savgol_coeffs

from mavsysid.errors import InputError

__all__ = [
    "AXIS_NAMES",
    "AXIS_UNITS",
    "MAX_JITTER",
    "SmoothedPose",
    "SmootherSettings",
    "acceleration_kernel",
    "body_force_readout",
    "body_rotation_readout",
    "consistent_accelerations",
    "convolve_columns",
    "model_accelerations",
    "noise_gain",
    "savgol_kernel",
    "smooth_pose",
    "uniform_step",
]

#: The six residual axes: body specific force (m/s²) and angular acceleration (rad/s²).
AXIS_NAMES = ("f_x", "f_y", "f_z", "dw_x", "dw_y", "dw_z")
AXIS_UNITS = ("m/s²",) * 3 + ("rad/s²",) * 3

#: Largest deviation of a sample interval from the median one, as a fraction of it, that
#: the smoother takes as uniform (the log is then used as it is).
MAX_JITTER = 0.05


def uniform_step(t: np.ndarray, source: str) -> float:
    """The sample interval of a uniformly sampled log, s; refuses any other.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Sample times, s.
    source : str
        The file the samples came from (named in the refusal).
    """
    dt = np.diff(t)
    step = float(np.median(dt)) if dt.size else 0.0
    if not step > 0.0 or np.max(np.abs(dt - step)) > MAX_JITTER * step:
        raise InputError(f"{source}: the pose log is not sampled at a uniform rate "
                         f"(jitter > {100 * MAX_JITTER:.0f} %); the diagnosis smoother "
                         "needs uniform samples")
    return step


@dataclass(frozen=True)
class SmootherSettings:
    """The Savitzky–Golay smoother that turns poses into accelerations.

    Attributes
    ----------
    window : float
        Window length, s. 0.6 s (cubic) takes the 0.5 mm / 0.1° motion-capture noise of
        the second derivatives down to ≈ 5 mm/s² and 0.02 rad/s² and still passes the
        rotors' influence up to ≈ 2 Hz (0.15 s: 0.15 m/s², too noisy for the effects).
    polyorder : int
        Degree of the local polynomial (≥ 2 for a second derivative).
    trim : float
        Time cut off each end of the flight, s: the smoother's edges are one-sided.
    input_window : float
        Window of the light smoother that gives the model its inputs (attitude, rates,
        velocity), s. The model's force is rotated to the world frame with this attitude:
        the long window's attitude lags the true one by a fraction of a milliradian,
        which times g is a spurious force of a few mm/s² — the size of the effects.
    """

    window: float = 0.6
    polyorder: int = 3
    trim: float = 0.5
    input_window: float = 0.1

    def samples(self, dt: float) -> int:
        """Odd window length in samples for sample time ``dt``."""
        n = max(self.polyorder + 2, round(self.window / dt))
        return n + 1 - n % 2


@dataclass(frozen=True)
class SmoothedPose:
    """A pose log smoothed and differentiated (N samples, uniform time step).

    Attributes
    ----------
    t : ndarray, shape (N,)
        s.
    position : ndarray, shape (N, 3)
        m, world ENU.
    quaternion : ndarray, shape (N, 4)
        Unit, body → world.
    velocity : ndarray, shape (N, 3)
        World velocity, m/s.
    acceleration : ndarray, shape (N, 3)
        World acceleration, m/s².
    rates : ndarray, shape (N, 3)
        Body rates ω, rad/s.
    angular_acceleration : ndarray, shape (N, 3)
        ω̇ in the body frame, rad/s².
    """

    t: np.ndarray
    position: np.ndarray
    quaternion: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    rates: np.ndarray
    angular_acceleration: np.ndarray

    def rotation(self) -> np.ndarray:
        """R(q) body → world, shape (N, 3, 3)."""
        return self._rotation

    @cached_property
    def _rotation(self) -> np.ndarray:
        # Read by every residual evaluation of the cached log smoothing.
        rotation = quat_to_matrix(self.quaternion)
        rotation.setflags(write=False)
        return rotation

    def velocity_body(self) -> np.ndarray:
        """v_B = Rᵀ v, shape (N, 3), m/s."""
        return np.einsum("nji,nj->ni", self.rotation(), self.velocity)

    def specific_force(self) -> np.ndarray:
        """f = Rᵀ(a − g), g = [0, 0, −9.81]: what the rotors and drag must produce, m/s²."""
        a = self.acceleration + np.array([0.0, 0.0, GRAVITY])
        return np.einsum("nji,nj->ni", self.rotation(), a)


def smooth_pose(t: np.ndarray, position: np.ndarray, quaternion: np.ndarray,
                settings: SmootherSettings, source: str = "pose log") -> SmoothedPose:
    """Savitzky–Golay smoothing and differentiation of a uniformly sampled pose log.

    The quaternion's components are smoothed as a signal (after making its sign
    continuous); ω = 2 Im(q* ⊗ q̇) and ω̇ = 2 Im(q* ⊗ q̈) (from q̇ = ½ q ⊗ [0, ω]: the
    ω ⊗ ω term of q̈ is real, so it drops out of the imaginary part).

    Parameters
    ----------
    t : ndarray, shape (N,)
    position : ndarray, shape (N, 3)
    quaternion : ndarray, shape (N, 4)
    settings : SmootherSettings
    source : str
        The file the pose came from, named in refusals.

    Returns
    -------
    SmoothedPose
    """
    dt = uniform_step(t, source)
    w = settings.samples(dt)
    if len(t) < 2 * w:
        raise InputError(f"{source}: {len(t)} pose samples: the diagnosis needs at least "
                         f"{2 * w}")
    q = continuous_sign(quaternion)

    signal = np.hstack([q, np.asarray(position, float)])
    # savgol_filter(mode="mirror") with the kernels computed once. Edge handling does not
    # matter (the edges are trimmed by every user), so the cheap mirror mode rather than
    # the default per-edge polynomial fits.
    smooth, first, second = (convolve1d(signal, savgol_kernel(w, settings.polyorder, d, dt),
                                        axis=0, mode="mirror") for d in (0, 1, 2))
    qs, qd, qdd = smooth[:, :4], first[:, :4], second[:, :4]
    norm = np.linalg.norm(qs, axis=1, keepdims=True)
    qs, qd, qdd = qs / norm, qd / norm, qdd / norm
    conj = qs * np.array([1.0, -1.0, -1.0, -1.0])
    rates = 2.0 * quat_multiply(conj, qd)[:, 1:]
    angular_acceleration = 2.0 * quat_multiply(conj, qdd)[:, 1:]
    return SmoothedPose(t=np.asarray(t, float), position=smooth[:, 4:], quaternion=qs,
                        velocity=first[:, 4:], acceleration=second[:, 4:], rates=rates,
                        angular_acceleration=angular_acceleration)


@lru_cache(maxsize=64)
def savgol_kernel(window: int, polyorder: int, deriv: int, dt: float) -> np.ndarray:
    """Savitzky–Golay convolution kernel (read-only), shape (window,), for ``convolve1d``."""
    kernel = savgol_coeffs(window, polyorder, deriv=deriv, delta=dt)
    kernel.setflags(write=False)
    return kernel


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


#: Kernel length from which the FFT's overlap-add beats the direct sum (measured: 3–4×
#: faster at 150 taps on 30 000 samples, equal near 64).
_FFT_TAPS = 64


def convolve_columns(x: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """``np.convolve(mode="same")`` per column: zero padding, an odd kernel centred.

    Parameters
    ----------
    x : ndarray, shape (N,) or (N, m)
        Signal, one column per channel.
    kernel : ndarray, shape (w,)
        Odd length.

    Returns
    -------
    ndarray, shape of ``x``
    """
    if kernel.size > _FFT_TAPS and x.shape[0] > kernel.size:
        out = oaconvolve(x, kernel.reshape((-1,) + (1,) * (x.ndim - 1)), mode="same", axes=0)
        return np.asarray(out, dtype=float)
    return convolve1d(x, kernel, axis=0, mode="constant", cval=0.0)


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


def body_force_readout(pose: SmoothedPose, inputs: SmoothedPose, force: np.ndarray,
                       kernel: np.ndarray) -> np.ndarray:
    """A body-frame model force (per unit mass) as the smoother sees it, shape (N, 3).

    The force is rotated to the world frame with the input attitude, filtered by
    ``kernel`` (`acceleration_kernel`, where the smoother acted on the position) and read
    back in the smoothed body frame. Linear in ``force``.

    Parameters
    ----------
    pose, inputs : SmoothedPose
        The measured side's smoothing and the model's input states.
    force : ndarray, shape (N, 3)
        Body force per unit mass, m/s².
    kernel : ndarray, shape (w,)
    """
    world = convolve_columns(np.einsum("nij,nj->ni", inputs.rotation(), force), kernel)
    return np.einsum("nji,nj->ni", pose.rotation(), world)


def body_rotation_readout(pose: SmoothedPose, inputs: SmoothedPose, omega_dot: np.ndarray,
                          kernel: np.ndarray, rate_term: bool = True) -> np.ndarray:
    """A model angular acceleration as the smoother sees it, shape (N, 3), rad/s².

    q̈ = q ⊗ (½[0, ω̇] − ¼‖ω‖² [1, 0]) at the input states, filtered by ``kernel``,
    read as 2 Im(q* ⊗ q̈) with the smoothed attitude. Without the ``rate_term`` it is
    linear in ``omega_dot``; the rate term alone is the readout of ω̇ = 0.

    Parameters
    ----------
    pose, inputs : SmoothedPose
    omega_dot : ndarray, shape (N, 3)
        Body angular acceleration, rad/s².
    kernel : ndarray, shape (w,)
    rate_term : bool
        Include the −¼‖ω‖² part of q̈.
    """
    scalar = -0.25 * np.sum(inputs.rates**2, axis=1) if rate_term else np.zeros(len(omega_dot))
    inner = np.column_stack([scalar, 0.5 * np.asarray(omega_dot, float)])
    qdd = convolve_columns(quat_multiply(inputs.quaternion, inner), kernel)
    conj = pose.quaternion * np.array([1.0, -1.0, -1.0, -1.0])
    return 2.0 * quat_multiply(conj, qdd)[:, 1:]


def acceleration_kernel(settings: SmootherSettings, dt: float) -> np.ndarray:
    """The smoother's action on an acceleration signal, shape (w,), unit sum.

    The second-derivative Savitzky–Golay kernel c annihilates constants and ramps, so
    c ∗ p = h ∗ Δ²p / dt² exactly with h = dt² · cumsum(cumsum(c)) (finite support), and
    Δ²p / dt² is the acceleration to O(dt²). Filtering the model's acceleration with h
    reproduces what the smoother does to the measured one, bias included.
    """
    return _acceleration_kernel(settings.samples(dt), settings.polyorder, dt)


@lru_cache(maxsize=16)
def _acceleration_kernel(window: int, polyorder: int, dt: float) -> np.ndarray:
    c = savgol_kernel(window, polyorder, 2, dt)
    h = np.cumsum(np.cumsum(c))[:-1] * dt**2
    # Centre h (length w − 1 after the double sum drops its zero tail) on w taps.
    h = np.concatenate([[0.0], h]) if len(h) % 2 == 0 else h
    h.setflags(write=False)
    return h


def noise_gain(settings: SmootherSettings, dt: float) -> float:
    """‖c‖ of the second-derivative smoother: acceleration noise per unit position noise.

    Used to document the noise floor: σ_a = σ_p ‖c‖ (white position noise, m → m/s²).
    """
    w = settings.samples(dt)
    return float(np.linalg.norm(savgol_kernel(w, settings.polyorder, 2, dt)))
