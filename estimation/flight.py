"""A flight as the estimator sees it, and the rotor speeds between its slow input samples.

`FlightData`: timed pose measurements and rotor speeds, what every log reader
(`mavsysid.estimation.readers.load_flight`) returns whatever the file format; frames are
already converted to ENU/FLU and units to SI. Gaps too long to bridge split it into
segments (`FlightData.segment_starts`).

`InputSamples`: a log's rotor speeds (measured rpm or commanded outputs) are sampled at
their own rate and interpolated to the pose times. Between two samples ``h`` s apart the
true speed is not the straight line; at fraction s ∈ [0, 1] of the interval a straight
line misses by

    e(s) ≈ −½ s (1 − s) h² n̈,

n̈ the rotor-speed curvature there. This error is systematic (a straight line cuts the
peak of every oscillation): for series sampled more slowly than `SMOOTH_PERIOD` the
interpolation subtracts it, with d = h² n̈ estimated at each sample from the samples'
second differences (divided differences for uneven spacing) and taken linear in between.

What remains is modelled as noise. The filter integrates the wrench over an interval, so
what matters is the error's mean over it, h² n̈ / 12 in size, persisting for the whole
interval: a random constant over h s, which white noise of spectral density
S = h · Cov(h² n̈ / 12) matches. For the interval between samples j and j + 1,

    S_j = h_j · (d_j d_jᵀ + d_{j+1} d_{j+1}ᵀ) / 144,

added at every filter step inside the interval (not at a sample itself, where the speed
is measured). On simulated excitation flights sampled at 4 to 20 Hz, the mean squared
interval error of plain linear interpolation was 0.6 to 1.0 of this S; faster motion than
the sampling resolves is aliased and can hide, so S is an estimate from the data, not a
bound. At ≥ 100 Hz S is negligible; at 4 Hz it is not. The density in rotor-speed terms
becomes process noise on the body force and torque through ∂[F, M]/∂n
(`wrench_noise_density`), which the parameter filter and the batch refinement add to the
configured process-noise density step by step (`step_process_noise`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np
from mavsysid.vehicle.mav_model import rotor_wrench
from mavsysid.vehicle.rotation import continuous_sign, quat_conjugate, quat_multiply, quat_to_matrix

__all__ = ["MIN_DURATION", "POSE_SOURCES", "SMOOTH_PERIOD", "FlightData", "Imu", "ImuSeries",
           "InputSamples", "step_process_noise", "wrench_noise_density"]


#: Input series sampled at least this often (median step, s) are interpolated linearly:
#: there the curvature term h² n̈ / 8 is below an ESC's rpm resolution and noise, which the
#: second differences would amplify instead of correcting.
SMOOTH_PERIOD = 0.1


def _curvature_terms(t: np.ndarray, n: np.ndarray) -> np.ndarray:
    """d_i = h_i² n̈_i at each sample, shape (M, k), rad/s; zero at the two ends."""
    d = np.zeros_like(n)
    if t.shape[0] < 3:
        return d
    h = np.diff(t)
    slope = np.diff(n, axis=0) / h[:, None]
    span = 0.5 * (h[:-1] + h[1:])
    curvature = np.diff(slope, axis=0) / span[:, None]
    d[1:-1] = curvature * (span**2)[:, None]
    # Across a gap the samples are too far apart to say anything about the curvature.
    wide = np.maximum(h[:-1], h[1:]) > 2.0 * np.median(h)
    d[1:-1][wide] = 0.0
    return d


def _locate(ts: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Interval j (between samples j, j + 1) of each time, and the fraction s ∈ [0, 1]."""
    j = np.clip(np.searchsorted(ts, t, side="right") - 1, 0, ts.shape[0] - 2)
    s = np.clip((t - ts[j]) / (ts[j + 1] - ts[j]), 0.0, 1.0)
    return j, s


@dataclass(frozen=True)
class InputSamples:
    """The rotor-speed samples as logged, before interpolation to the pose times.

    Attributes
    ----------
    series : tuple of (ndarray (M,), ndarray (M, m))
        Each input series' strictly increasing times, s (the flight's clock), and its
        rotor speeds, rad/s; columns concatenated in order are rotors 1..k.
    """

    series: tuple[tuple[np.ndarray, np.ndarray], ...]

    @property
    def slowest_rate(self) -> float | None:
        """The slowest series' median sample rate, Hz; None without two distinct times."""
        rates = []
        for ts, _ in self.series:
            steps = np.diff(np.asarray(ts, float))
            steps = steps[steps > 0.0]
            if steps.size:
                rates.append(1.0 / float(np.median(steps)))
        return min(rates) if rates else None

    def scaled(self, rotor: int, factor: float) -> InputSamples:
        """These samples with rotor ``rotor``'s speeds (0-based) multiplied by ``factor``.

        Parameters
        ----------
        rotor : int
            Index among the concatenated columns.
        factor : float
            The scale.
        """
        series, first = [], 0
        for ts, vs in self.series:
            if first <= rotor < first + vs.shape[1]:
                vs = vs.copy()
                vs[:, rotor - first] *= factor
            series.append((ts, vs))
            first += vs.shape[1]
        return InputSamples(tuple(series))

    def interpolate(self, t: np.ndarray) -> np.ndarray:
        """Rotor speeds at times ``t`` (N,), rad/s, shape (N, k): linear, curvature-corrected.

        Between samples j and j + 1 the straight line minus ½ s (1 − s) d(s), d = h² n̈
        interpolated linearly between the samples' second differences: this removes the
        leading interpolation error above, which is systematic (a straight line cuts the
        peaks of every oscillation, so an estimate from it is biased, not only noisy).
        At the samples themselves it is the sample; outside their span, the end sample.
        Series sampled at least every `SMOOTH_PERIOD` s are interpolated linearly.
        """
        t = np.asarray(t, dtype=float)
        columns = []
        for ts, vs in self.series:
            if ts.shape[0] < 2:
                columns.append(np.repeat(vs[:1], t.shape[0], axis=0))
                continue
            j, s = _locate(ts, t)
            line = vs[j] + s[:, None] * (vs[j + 1] - vs[j])
            if np.median(np.diff(ts)) < SMOOTH_PERIOD:
                columns.append(line)
                continue
            d = _curvature_terms(ts, vs)
            bend = d[j] + s[:, None] * (d[j + 1] - d[j])
            columns.append(line - 0.5 * (s * (1.0 - s))[:, None] * bend)
        return np.column_stack(columns)

    def density(self, t: np.ndarray) -> np.ndarray:
        """Spectral density of the interpolation error at times ``t``.

        Parameters
        ----------
        t : ndarray, shape (N,)
            Times the rotor speeds were interpolated to, s.

        Returns
        -------
        ndarray, shape (N, k, k)
            S (see the module docstring), (rad/s)²·s; block diagonal across series
            (series are sampled independently).
        """
        t = np.asarray(t, dtype=float)
        k = sum(v.shape[1] for _, v in self.series)
        out = np.zeros((t.shape[0], k, k))
        col = 0
        for ts, vs in self.series:
            m = vs.shape[1]
            if ts.shape[0] >= 2:
                d = _curvature_terms(ts, vs)
                outer = d[:, :, None] * d[:, None, :]
                # Interval j: between samples j and j + 1.
                C = outer[:-1] + outer[1:]
                S = np.diff(ts)[:, None, None] * C / 144.0
                j, s = _locate(ts, t)
                # At a sample itself the rotor speed is measured, not interpolated.
                inside = (s > 1e-9) & (s < 1.0 - 1e-9)
                out[:, col:col + m, col:col + m] = S[j] * inside[:, None, None]
            col += m
        return out


def wrench_noise_density(n: np.ndarray, density: np.ndarray, theta: np.ndarray,
                         r: np.ndarray, eps: np.ndarray) -> np.ndarray:
    """The rotor-speed error density as body force and torque noise density.

    Parameters
    ----------
    n : ndarray, shape (N, k)
        Rotor speeds, rad/s, where the Jacobian is taken.
    density : ndarray, shape (N, k, k)
        Rotor-speed error density S, (rad/s)²·s (`InputSamples.density`).
    theta : ndarray, shape (6,)
        θ, SI, for the Jacobian (the prior's: the density is an uncertainty, the
        nominal θ is close enough for its size).
    r : ndarray, shape (k, 3)
        Rotor positions, m, body frame.
    eps : ndarray, shape (k,)
        Spin directions, ±1.

    Returns
    -------
    ndarray, shape (N, 6, 6)
        J S Jᵀ with J = ∂[F_B, M_B]/∂n (at hover velocity and rates, zero: the drag
        terms' share is second order), in N²·s and N²·m²·s, the units of the filter's
        process-noise density.
    """
    n = np.asarray(n, dtype=float)
    zeros = np.zeros((n.shape[0], 3))
    force, torque = rotor_wrench(n, theta, r, eps, zeros, zeros)
    base = np.column_stack([force, torque])
    J = np.empty((n.shape[0], 6, n.shape[1]))
    for i in range(n.shape[1]):
        step = 1e-3 * np.maximum(np.abs(n[:, i]), 1.0)
        moved = n.copy()
        moved[:, i] += step
        f, m = rotor_wrench(moved, theta, r, eps, zeros, zeros)
        J[:, :, i] = (np.column_stack([f, m]) - base) / step[:, None]
    return J @ density @ J.transpose(0, 2, 1)


def step_process_noise(Qc: np.ndarray, t: np.ndarray, n: np.ndarray,
                       inputs: InputSamples | None, theta: np.ndarray, r: np.ndarray,
                       eps: np.ndarray) -> np.ndarray:
    """The process-noise density of each filter step: configured plus input error.

    Parameters
    ----------
    Qc : ndarray, shape (6, 6)
        The configured force and moment noise density, N²·s and N²·m²·s.
    t : ndarray, shape (N,)
        The flight's sample times, s.
    n : ndarray, shape (N, k)
        The rotor speeds at ``t``, rad/s.
    inputs : InputSamples or None
        The rotor-speed samples as logged; None adds nothing.
    theta, r, eps
        As for `wrench_noise_density`.

    Returns
    -------
    ndarray, shape (N, 6, 6)
        Row i is the density of the step from sample i to i + 1 (the last row unused).
    """
    out = np.repeat(np.asarray(Qc, dtype=float)[None], np.shape(t)[0], axis=0)
    if inputs is not None:
        out += wrench_noise_density(n, inputs.density(t), theta, r, eps)
    return out


#: Shortest flight worth estimating from, s: the log checks and the estimator both refuse
#: less.
MIN_DURATION = 2.0

#: Where the pose came from: raw motion capture, or the autopilot's own (filtered,
#: lagged) estimator, which calls for a larger measurement noise.
POSE_SOURCES = ("motion_capture", "autopilot")


@dataclass(frozen=True)
class ImuSeries:
    """One inertial sensor's samples (M of them), in the body frame (FLU).

    Attributes
    ----------
    t : ndarray, shape (M,)
        Sample times, s, on the log's clock, strictly increasing.
    values : ndarray, shape (M, 3)
        Body rates (rad/s) of a gyro, or the specific force (m/s², +9.81 on z level at
        rest) of an accelerometer.
    cutoff_hz : float or None
        The low-pass the samples went through before logging, Hz; 0 for raw samples, None
        when the log does not say.
    label : str
        What the samples are, for messages ("IMU GyrX..Z", "HIGHRES_IMU", …).
    """

    t: np.ndarray
    values: np.ndarray
    cutoff_hz: float | None = None
    label: str = "IMU"

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def rate(self) -> float:
        """Median sample rate, Hz (0 for fewer than two samples)."""
        return 1.0 / float(np.median(np.diff(self.t))) if len(self) > 1 else 0.0

    def time_slice(self, t0: float, t1: float) -> ImuSeries:
        """The samples with t0 ≤ t ≤ t1.

        Parameters
        ----------
        t0, t1 : float
            The span, s on the log's clock.
        """
        keep = (self.t >= t0) & (self.t <= t1)
        return replace(self, t=self.t[keep], values=self.values[keep])


@dataclass(frozen=True)
class Imu:
    """The vehicle's IMU as logged: its gyro and accelerometer, where it sits.

    Attributes
    ----------
    gyro, accel : ImuSeries or None
        Body rates and specific force, each at its own rate (the pose's or faster).
    position : ndarray, shape (3,), or None
        The IMU's offset from the centre of gravity, m, body FLU (the vehicle file's
        ``[imu] position``, else the log's, e.g. ArduPilot ``INS_POS1_*``); None: not
        stated, estimated where the data allow.
    """

    gyro: ImuSeries | None
    accel: ImuSeries | None
    position: np.ndarray | None = None

    def time_slice(self, t0: float, t1: float) -> Imu:
        """The samples with t0 ≤ t ≤ t1.

        Parameters
        ----------
        t0, t1 : float
            The span, s on the log's clock.
        """
        return replace(self, gyro=None if self.gyro is None else self.gyro.time_slice(t0, t1),
                       accel=None if self.accel is None else self.accel.time_slice(t0, t1))


@dataclass(frozen=True)
class FlightData:
    """Samples of one flight, N of them.

    Attributes
    ----------
    t : ndarray, shape (N,)
        Time, s, strictly increasing.
    position : ndarray, shape (N, 3)
        Measured position, m, world ENU.
    quaternion : ndarray, shape (N, 4)
        Measured attitude, unit ``[w, x, y, z]``, body FLU → world ENU.
    rotor_speeds : ndarray, shape (N, k)
        Actual rotor speeds, rad/s, in the vehicle config's rotor order.
    source : str
        The file it was read from (with ``+ pose FILE`` when merged).
    pose_source : {"motion_capture", "autopilot"}
        Origin of the pose measurements.
    truth : dict or None
        The ``truth`` block of a simulated flight's meta.json (true parameters under
        ``"parameters"``), if any. Never used by estimation, only for reporting errors.
    warnings : tuple of str
        Problems found and repaired while reading (NaN rows dropped, …), one line each.
    segment_starts : tuple of int
        Index of the first sample of each contiguous segment, increasing, starting with 0:
        a gap too long to bridge separates two segments (see
        `mavsysid.estimation.readers.samples`). One segment, ``(0,)``, by default.
    inputs : InputSamples or None
        The rotor-speed samples as logged, before interpolation to ``t``: the filter adds
        the interpolation error as process noise (`mavsysid.estimation.flight`).
        None: the rotor speeds are exact at ``t`` (as in a pose log).
    imu : Imu or None
        The vehicle's IMU over the flight, at its own rates; None when the log has none.
    rotor_scale_sigma : float
        Relative 1σ of the rotor speeds' common scale: the motor curve's, where they are
        motor outputs through it (the vehicle file's ``[motor] curve_sigma``, or its fit
        to the log's own ESC rpm); 0 where they are measured or exact. c_T and c_M go as
        its square; c_D and J do not depend on it.
    """

    t: np.ndarray
    position: np.ndarray
    quaternion: np.ndarray
    rotor_speeds: np.ndarray
    source: str
    pose_source: Literal["motion_capture", "autopilot"] = "motion_capture"
    truth: dict | None = None
    warnings: tuple[str, ...] = field(default_factory=tuple)
    segment_starts: tuple[int, ...] = (0,)
    inputs: InputSamples | None = None
    imu: Imu | None = None
    rotor_scale_sigma: float = 0.0

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def duration(self) -> float:
        """Time span of the samples, s."""
        return float(self.t[-1] - self.t[0]) if len(self) else 0.0

    @property
    def pose_rate(self) -> float:
        """Pose samples per second, Hz: the reciprocal of the median sample interval (NaN
        with fewer than two samples)."""
        if len(self) < 2:
            return math.nan
        return float(1.0 / np.median(np.diff(np.asarray(self.t, float))))

    @property
    def rotor_count(self) -> int:
        """k, the number of rotor-speed columns."""
        return int(self.rotor_speeds.shape[1])

    @property
    def true_theta(self) -> np.ndarray | None:
        """True θ (6,) when the flight was simulated, else None."""
        if not self.truth or "parameters" not in self.truth:
            return None
        p = self.truth["parameters"]
        return np.array([p["c_T"], p["c_D"], p["c_M"], p["j_x"], p["j_y"], p["j_z"]], float)

    @property
    def segment_bounds(self) -> list[tuple[int, int]]:
        """``(start, stop)`` sample indices of each segment (``stop`` exclusive)."""
        ends = (*self.segment_starts[1:], len(self))
        return list(zip(self.segment_starts, ends, strict=True))

    def segment(self, index: int) -> FlightData:
        """Segment ``index`` alone, as a one-segment flight."""
        start, stop = self.segment_bounds[index]
        return replace(self, t=self.t[start:stop], position=self.position[start:stop],
                       quaternion=self.quaternion[start:stop],
                       rotor_speeds=self.rotor_speeds[start:stop], segment_starts=(0,))

    def longest_segment(self) -> int:
        """Index of the segment spanning the most time (the first of equals)."""
        spans = [self.t[stop - 1] - self.t[start] for start, stop in self.segment_bounds]
        return int(np.argmax(spans))

    def pose_states(self) -> np.ndarray:
        """Model states [p, v_B, q, ω] from the logged pose alone, shape (N, 13).

        Velocity and body rates are central differences of the pose: where the nuisance
        quantities' terms are evaluated before any filter pass (most depend on the rotor
        speeds and time only; a velocity-dependent one sees the pose's noise through them).
        """
        t = np.asarray(self.t, float)
        q = continuous_sign(self.quaternion)
        x = np.zeros((len(t), 13))
        x[:, 0:3] = self.position
        x[:, 6:10] = q
        if len(t) < 2:
            return x
        velocity = np.gradient(np.asarray(self.position, float), t, axis=0)
        x[:, 3:6] = np.einsum("nji,nj->ni", quat_to_matrix(q), velocity)
        q_dot = np.gradient(q, t, axis=0)
        x[:, 10:13] = 2.0 * quat_multiply(quat_conjugate(q), q_dot)[:, 1:]
        return x

    def time_slice(self, t0: float, t1: float) -> FlightData:
        """The samples with t0 ≤ t ≤ t1 (segments kept where they start inside)."""
        keep = (self.t >= t0) & (self.t <= t1)
        # One contiguous time range: a segment start cut off lies before t0 or after t1.
        index = np.cumsum(keep) - 1
        starts = sorted({0, *(int(index[s]) for s in self.segment_starts if keep[s])})
        return replace(self, t=self.t[keep], position=self.position[keep],
                       quaternion=self.quaternion[keep], rotor_speeds=self.rotor_speeds[keep],
                       segment_starts=tuple(starts),
                       imu=None if self.imu is None else self.imu.time_slice(t0, t1))
