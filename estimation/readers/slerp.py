"""Spherical linear interpolation (slerp) of attitude quaternions between their samples.

Used where attitudes sampled at one set of times are needed at others: combining a log's
position and attitude, aligning clocks, resampling a flight.
"""

from __future__ import annotations

import numpy as np
from mavsysid.vehicle.rotation import quat_conjugate, quat_exp, quat_log, quat_multiply

__all__ = ["interpolate_quaternions"]


def interpolate_quaternions(t: np.ndarray, q: np.ndarray, t_new: np.ndarray) -> np.ndarray:
    """Spherical linear interpolation of unit quaternions.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Sample times, s, strictly increasing, N ≥ 2.
    q : ndarray, shape (N, 4)
        Unit quaternions ``[w, x, y, z]`` at `t`.
    t_new : ndarray, shape (M,)
        Times to interpolate at, s, within ``[t[0], t[-1]]``.

    Returns
    -------
    ndarray, shape (M, 4)
        q(t_new), along the shorter arc between neighbouring samples.
    """
    t_new = np.asarray(t_new, dtype=float)
    i = np.clip(np.searchsorted(t, t_new, side="right") - 1, 0, len(t) - 2)
    s = ((t_new - t[i]) / (t[i + 1] - t[i]))[:, None]
    q0 = q[i]
    # q0 ⊗ Exp(s Log(q0⁻¹ ⊗ q1)); quat_log takes the shorter rotation, so a sign flip
    # between neighbours (q and −q are one attitude) does not send the path the long way.
    delta = quat_log(quat_multiply(quat_conjugate(q0), q[i + 1]))
    return quat_multiply(q0, quat_exp(s * delta))
