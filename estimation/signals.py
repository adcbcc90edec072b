"""The signals of a flight: uniform grids, smoothing and derivatives, the pose's own noise.

**Uniform grids** (`uniform_segments`). Real logs repeat the pose: a logger running
faster than the on-board estimator writes the last estimate again (a Crazyflie's 500 Hz
uSD log repeats about half its rows), and a lost radio packet repeats a row. A repeated
pose is a measurement of an earlier time; taken at face value it makes the position a
staircase whose second derivative is noise. So a row whose position and attitude both
equal the previous row's exactly is left out (`fresh_pose`), and the fresh samples are
interpolated onto a uniform grid at the log's median step (linear in position and in the
sign-continuous quaternion, renormalised). The rotor speeds keep every row:
`UniformSegment.rotor_speeds` interpolates them at t − δ, for a pose that lags them by δ.

**Smoothing and derivatives** (`smooth_pose`). A Savitzky–Golay smoother turns poses
into velocity, acceleration, body rates and angular acceleration: the quaternion's
components are smoothed as a signal (sign made continuous), ω = 2 Im(q* ⊗ q̇) and
ω̇ = 2 Im(q* ⊗ q̈). Whatever is compared with the smoothed measurement goes through the
same smoother (`acceleration_kernel`, `body_force_readout`, `body_rotation_readout`), so
its attenuation of fast content applies to both sides and cancels.

**Band-pass** (`Band`): a zero-phase Butterworth band (or low-pass) along time, applied
alike to both sides of a balance.

**States from the pose** (`pose_states`): position, attitude and their central
differences, where the nuisance quantities' terms are evaluated before a filter pass.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np
from mavsysid.estimation.flight import FlightData
from mavsysid.vehicle.config import GRAVITY
from mavsysid.vehicle.rotation import continuous_sign, quat_multiply, quat_to_matrix
from scipy.ndimage import convolve1d
from scipy.signal import oaconvolve, savgol_coeffs

from mavsysid.errors import InputError

__all__ = ["MAX_JITTER", "ImuSegment", "Segment", "SmoothedPose", "SmootherSettings",
           "UniformSegment",
           "acceleration_kernel", "balance_segments", "body_force_readout", "body_rotation_readout",
           "convolve_columns", "fresh_pose", "imu_segments", "noise_gain", "rate_kernel",
           "savgol_kernel", "smooth_pose", "uniform_segments", "uniform_step"]


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


def rate_kernel(settings: SmootherSettings, dt: float) -> np.ndarray:
    """The first-derivative smoother's action on an angular acceleration, shape (w,).

    The derivative kernel c annihilates constants, so c ∗ ω = h ∗ ω̇ with h = dt ·
    cumsum(c), the step response of c; averaged over half-sample shifts so that it is
    centred on the window's odd length (ω sampled, ω̇ the derivative between samples).
    Filtering the model's ω̇ with h reproduces what differentiating the gyro does.

    Parameters
    ----------
    settings : SmootherSettings
        The derivative's Savitzky–Golay window and order.
    dt : float
        The sample interval, s.
    """
    return _rate_kernel(settings.samples(dt), settings.polyorder, dt)


@lru_cache(maxsize=16)
def _rate_kernel(window: int, polyorder: int, dt: float) -> np.ndarray:
    h = np.cumsum(savgol_kernel(window, polyorder, 1, dt))[:-1] * dt
    h = np.concatenate([[0.5 * h[0]], 0.5 * (h[1:] + h[:-1]), [0.5 * h[-1]]])
    h.setflags(write=False)
    return h


def noise_gain(settings: SmootherSettings, dt: float) -> float:
    """‖c‖ of the second-derivative smoother: acceleration noise per unit position noise.

    Used to document the noise floor: σ_a = σ_p ‖c‖ (white position noise, m → m/s²).
    """
    w = settings.samples(dt)
    return float(np.linalg.norm(savgol_kernel(w, settings.polyorder, 2, dt)))


def fresh_pose(position: np.ndarray, quaternion: np.ndarray) -> np.ndarray:
    """Rows whose pose differs from the previous row's, shape (N,) bool.

    Parameters
    ----------
    position : ndarray, shape (N, 3)
        m.
    quaternion : ndarray, shape (N, 4)
        Unit, [w, x, y, z].

    Returns
    -------
    ndarray of bool, shape (N,)
        True for the first row and every row not repeating its predecessor exactly.
    """
    pose = np.hstack([np.asarray(position, float), np.asarray(quaternion, float)])
    repeat = np.all(np.diff(pose, axis=0) == 0.0, axis=1)
    return np.concatenate([[True], ~repeat])


def _interp_columns(t_new: np.ndarray, t: np.ndarray, x: np.ndarray) -> np.ndarray:
    return np.column_stack([np.interp(t_new, t, x[:, j]) for j in range(x.shape[1])])


class _RotorsOnGrid:
    """Rotor speeds logged at their own times, read on a segment's grid ``t``."""

    t: np.ndarray
    rotor_time: np.ndarray
    rotor_samples: np.ndarray

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def rotor_step(self) -> float:
        """The median interval of the logged rotor speeds, s."""
        return float(np.median(np.diff(self.rotor_time))) if self.rotor_time.size > 1 else 0.0

    def rotor_speeds(self, delay: float = 0.0) -> np.ndarray:
        """Rotor speeds at t − ``delay`` on the grid, shape (M, k), rad/s.

        Parameters
        ----------
        delay : float
            s by which the grid's samples (pose or IMU) lag the rotor speeds (held at the
            ends).
        """
        return _interp_columns(self.t - delay, self.rotor_time, self.rotor_samples)


@dataclass(frozen=True)
class UniformSegment(_RotorsOnGrid):
    """One contiguous stretch of a flight on a uniform grid (M samples).

    Attributes
    ----------
    t : ndarray, shape (M,)
        Grid times, s, uniform step ``dt``.
    dt : float
        Grid step, s.
    position : ndarray, shape (M, 3)
        m, world ENU, interpolated from the fresh pose samples.
    quaternion : ndarray, shape (M, 4)
        Unit, body → world, sign-continuous.
    rotor_time : ndarray, shape (K,)
        Times of the logged rotor speeds, s.
    rotor_samples : ndarray, shape (K, k)
        Logged rotor speeds, rad/s.
    fresh_fraction : float
        Fraction of the segment's rows whose pose was fresh.
    flight_start : float
        The time the flight starts, s (time-dependent model terms count from it).
    """

    t: np.ndarray
    dt: float
    position: np.ndarray
    quaternion: np.ndarray
    rotor_time: np.ndarray
    rotor_samples: np.ndarray
    fresh_fraction: float
    flight_start: float = 0.0



def _segment(t: np.ndarray, position: np.ndarray, quaternion: np.ndarray,
             rotors: np.ndarray, dt: float, flight_start: float) -> UniformSegment | None:
    fresh = fresh_pose(position, quaternion)
    tf = t[fresh]
    if tf.size < 4:
        return None
    grid = tf[0] + dt * np.arange(int(np.floor((tf[-1] - tf[0]) / dt)) + 1)
    p = _interp_columns(grid, tf, position[fresh])
    q = _interp_columns(grid, tf, continuous_sign(quaternion[fresh]))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return UniformSegment(grid, dt, p, q, np.asarray(t, float), np.asarray(rotors, float),
                          float(fresh.mean()), flight_start)


def uniform_segments(flight: FlightData, min_duration: float) -> list[UniformSegment]:
    """Each segment of ``flight`` spanning at least ``min_duration`` s, on a uniform grid.

    Parameters
    ----------
    flight : FlightData
        Pose and rotor speeds at the pose times.
    min_duration : float
        Shortest segment kept, s.

    Returns
    -------
    list of UniformSegment
        In time order; the grid step is the median sample interval of the whole flight.
    """
    t = np.asarray(flight.t, float)
    if t.size < 2:
        return []
    dt = float(np.median(np.diff(t)))
    out = []
    for start, stop in flight.segment_bounds:
        if stop - start < 4 or t[stop - 1] - t[start] < min_duration:
            continue
        seg = _segment(t[start:stop], flight.position[start:stop],
                       flight.quaternion[start:stop], flight.rotor_speeds[start:stop], dt,
                       float(t[0]))
        if seg is not None and seg.t[-1] - seg.t[0] >= min_duration:
            out.append(seg)
    return out


#: Window of the smoother that gives an IMU segment the pose's velocity, s: the rotor drag
#: needs the velocity, which changes slowly; a short window passes a 5 Hz GPS pose.
VELOCITY_WINDOW = 0.4


@dataclass(frozen=True)
class ImuSegment(_RotorsOnGrid):
    """One contiguous stretch of a flight on the IMU's uniform grid (M samples).

    Attributes
    ----------
    t : ndarray, shape (M,)
        Grid times, s, uniform step ``dt`` (the gyro's median step).
    dt : float
        Grid step, s.
    gyro : ndarray, shape (M, 3)
        Body rates, rad/s, FLU.
    accel : ndarray, shape (M, 3)
        Specific force, m/s², FLU.
    velocity_body : ndarray, shape (M, 3)
        The pose's smoothed velocity in the body frame, m/s.
    position : ndarray, shape (M, 3)
        m, world ENU.
    quaternion : ndarray, shape (M, 4)
        Unit, body → world.
    rotor_time : ndarray, shape (K,)
        Times of the logged rotor speeds, s.
    rotor_samples : ndarray, shape (K, k)
        Logged rotor speeds, rad/s.
    flight_start : float
        The time the flight starts, s.
    imu_position : ndarray, shape (3,), or None
        The IMU's stated offset from the centre of gravity, m, body FLU.
    pose_position : ndarray, shape (M, 3), or None
        The fresh pose's position interpolated onto the grid, m: where the balance takes
        the specific force from the pose (motion capture) rather than the accelerometer.
    pose_quaternion : ndarray, shape (M, 4), or None
        Its attitude likewise, unit, sign-continuous.
    gyro_cutoff_hz, accel_cutoff_hz : float or None
        The low-pass each sensor went through before logging, Hz (None or 0: none known).
    """

    t: np.ndarray
    dt: float
    gyro: np.ndarray
    accel: np.ndarray
    velocity_body: np.ndarray
    position: np.ndarray
    quaternion: np.ndarray
    rotor_time: np.ndarray
    rotor_samples: np.ndarray
    flight_start: float = 0.0
    imu_position: np.ndarray | None = None
    pose_position: np.ndarray | None = None
    pose_quaternion: np.ndarray | None = None
    gyro_cutoff_hz: float | None = None
    accel_cutoff_hz: float | None = None



def _imu_segment(flight: FlightData, pose: UniformSegment, dt: float, force_from_pose: bool
                 ) -> ImuSegment | None:
    imu = flight.imu
    assert imu is not None and imu.gyro is not None and imu.accel is not None
    t0, t1 = pose.t[0], pose.t[-1]
    # The readers leave held readings out (`mavsysid.estimation.readers.samples`).
    tg, gyro = _span(imu.gyro.t, imu.gyro.values, t0, t1)
    ta, accel = _span(imu.accel.t, imu.accel.values, t0, t1)
    if tg.size < 4 or ta.size < 4:
        return None
    start, stop = max(tg[0], ta[0]), min(tg[-1], ta[-1])
    grid = start + dt * np.arange(int(np.floor((stop - start) / dt)) + 1)
    settings = SmootherSettings(window=max(VELOCITY_WINDOW, 5 * pose.dt), polyorder=2)
    if len(pose) < 2 * settings.samples(pose.dt):
        return None
    smoothed = smooth_pose(pose.t, pose.position, pose.quaternion, settings, flight.source)
    q = _interp_columns(grid, pose.t, smoothed.quaternion)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    velocity = _interp_columns(grid, pose.t, smoothed.velocity)
    velocity_body = np.einsum("nji,nj->ni", quat_to_matrix(q), velocity)
    gyro = _interp_columns(grid, tg, gyro)
    gyro = gyro - _gyro_bias(gyro, _interp_columns(grid, pose.t, smoothed.rates),
                             settings.samples(dt))
    raw_p = raw_q = None
    if force_from_pose:
        raw_p = _interp_columns(grid, pose.t, pose.position)
        raw_q = _interp_columns(grid, pose.t, pose.quaternion)
        raw_q /= np.linalg.norm(raw_q, axis=1, keepdims=True)
    return ImuSegment(grid, dt, gyro, _interp_columns(grid, ta, accel),
                      velocity_body, _interp_columns(grid, pose.t, smoothed.position), q,
                      *_rotor_series(flight, pose), pose.flight_start,
                      None if imu.position is None else np.asarray(imu.position, float),
                      raw_p, raw_q, imu.gyro.cutoff_hz, imu.accel.cutoff_hz)


def _rotor_series(flight: FlightData, pose: UniformSegment) -> tuple[np.ndarray, np.ndarray]:
    """The rotor speeds as logged over the segment, where they come as one series at their
    own rate (an autopilot's motor outputs, faster than its pose), else at the pose's rows."""
    inputs = flight.inputs
    if inputs is None or len(inputs.series) != 1:
        return pose.rotor_time, pose.rotor_samples
    t, values = inputs.series[0]
    inside = np.flatnonzero((t >= pose.t[0]) & (t <= pose.t[-1]))
    if inside.size < 4:
        return pose.rotor_time, pose.rotor_samples
    keep = slice(max(inside[0] - 1, 0), inside[-1] + 2)
    return np.asarray(t[keep], float), np.asarray(values[keep], float)


def _gyro_bias(gyro: np.ndarray, pose_rates: np.ndarray, edge: int) -> np.ndarray:
    """The gyro's constant bias against the pose's rates, rad/s, shape (3,).

    The balance's gyroscopic terms multiply two rates, so a bias b adds b_z ω_y + b_y ω_z
    to ω̇_x: at 0.005 rad/s and 1 rad/s of motion, 0.5 % of the roll torque, which biases
    j_x by as much. The attitude is free of it, and its rates' mean over the segment
    (the smoother keeps the mean; its one-sided edges are left out) is the gyro's less b.
    """
    inner = slice(edge, max(edge + 1, len(gyro) - edge))
    return np.mean(gyro[inner] - pose_rates[inner], axis=0)


def _span(t: np.ndarray, values: np.ndarray, t0: float, t1: float
          ) -> tuple[np.ndarray, np.ndarray]:
    keep = (t >= t0) & (t <= t1)
    return t[keep], values[keep]


def imu_segments(flight: FlightData, min_duration: float, force_from_pose: bool = False
                 ) -> list[ImuSegment]:
    """Each segment of ``flight`` spanning at least ``min_duration`` s, on the IMU's grid.

    The pose's segments (`uniform_segments`) bound them; within each, the gyro and the
    accelerometer (fresh samples) are interpolated onto a grid at the gyro's median step,
    and the pose's smoothed velocity, position and attitude onto the same grid. The gyro's
    constant bias, measured against the pose's rates, is taken off (`_gyro_bias`).

    Parameters
    ----------
    flight : FlightData
        With both IMU sensors (``flight.imu.gyro`` and ``.accel``).
    min_duration : float
        Shortest segment kept, s.
    force_from_pose : bool
        Keep the raw pose on the grid too (`ImuSegment.pose_position`), for a specific
        force from the pose.

    Returns
    -------
    list of ImuSegment
        In time order; empty when the flight has no gyro or no accelerometer.
    """
    imu = flight.imu
    if imu is None or imu.gyro is None or imu.accel is None or len(imu.gyro) < 2:
        return []
    tg = imu.gyro.t
    steps = np.diff(tg)
    dt = float(np.median(steps[steps > 0.0])) if np.any(steps > 0.0) else 0.0
    if not dt > 0.0:
        return []
    out = []
    for pose in uniform_segments(flight, min_duration):
        seg = _imu_segment(flight, pose, dt, force_from_pose)
        if seg is not None and seg.t[-1] - seg.t[0] >= min_duration:
            out.append(seg)
    return out


#: A stretch of flight the balance reads: the pose's grid, or the IMU's.
Segment = UniformSegment | ImuSegment


def balance_segments(flight: FlightData, min_duration: float) -> list[Segment]:
    """The flight's segments for the balance: on the IMU's grid where it has a gyro and an
    accelerometer (`imu_segments`), else on the pose's (`uniform_segments`).

    The angular acceleration is then always the gyro's one derivative. The specific force
    is the pose's second derivative where the pose is motion capture (tied to gravity, free
    of the accelerometer's bias and scale error, precise at the balance's low band), the
    accelerometer's where it is an autopilot's own estimate (which fuses that
    accelerometer, lagged).

    Parameters
    ----------
    flight : FlightData
    min_duration : float
        Shortest segment kept, s.
    """
    from_pose = flight.pose_source == "motion_capture"
    return (imu_segments(flight, min_duration, from_pose)
            or uniform_segments(flight, min_duration))
