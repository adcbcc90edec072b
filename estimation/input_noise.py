"""Rotor speeds between slow input samples: interpolation and the uncertainty it leaves.

A log's rotor speeds (measured rpm or commanded outputs) are sampled at their own rate
and interpolated to the pose times. Between two samples ``h`` s apart the true speed is
not the straight line; at fraction s ∈ [0, 1] of the interval a straight line misses by

    e(s) ≈ −½ s (1 − s) h² n̈,

n̈ the rotor-speed curvature there. This error is systematic (a straight line cuts the
peak of every oscillation, so an estimate from it is biased): for series sampled more
slowly than `SMOOTH_PERIOD` the interpolation subtracts it, with d = h² n̈ estimated at
each sample from the samples' second differences (divided differences for uneven
spacing; for even spacing d_i = n_{i+1} − 2 n_i + n_{i−1}) and taken linear in between.

What remains is modelled as noise. The filter integrates the wrench over an interval,
so what matters is the error's mean over it, h² n̈ / 12 in size, persisting for the
whole interval: a random constant over h s. White noise of spectral density S spreads
the same integrated variance over h when S = h · Cov(h² n̈ / 12). So, for the interval
between samples j and j + 1,

    S_j = h_j · (d_j d_jᵀ + d_{j+1} d_{j+1}ᵀ) / 144,

added at every filter step inside the interval (not at a sample itself, where the speed
is measured). Assumptions: the rotor speed is smooth on the scale of h, so second
differences measure its curvature; the interval's curvature is bounded by what its two
ends see, and the sum (not the mean) of the two keeps curvature concentrated inside the
interval; the errors of successive intervals are independent; the full k × k covariance
keeps the rotors' correlation (a climb moves all of them together). The same S is used
after the curvature correction, for which it is an upper estimate: the correction's own
error comes from the same curvature. On simulated excitation flights sampled at 4 to
20 Hz, the mean squared interval error of plain linear interpolation was 0.6 to 1.0 of
this S; faster motion than the sampling resolves is aliased and can hide, so S is an
estimate from the data, not a bound. At ≥ 100 Hz S is negligible; at 4 Hz it is not.

The density in rotor-speed terms becomes process noise on the body force and torque
through ∂[F, M]/∂n (`wrench_noise_density`), which the parameter filter and the batch
refinement add to the configured process-noise density step by step
(`step_process_noise`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from mavsysid.vehicle.mav_model import rotor_wrench

__all__ = ["SMOOTH_PERIOD", "InputSamples", "step_process_noise", "wrench_noise_density"]

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
