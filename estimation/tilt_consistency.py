"""Does the logged motion agree with the logged attitude? Refuse a log whose clock or
position scale is wrong.

A multirotor's rotor thrust points along its body z axis, so the horizontal acceleration
follows the tilt: a_h = (a_z + g) b_h / b_z, with b = R e_z the body z axis in the world
(ENU) — independent of c_T, mass and inertia, which the estimate is to find. Rotor and
body drag add a force about linear in the velocity, and wind, a mounting offset of the
attitude sensor or a steady bias add a constant; so per horizontal axis

    a_h = λ (a_z + g) b_h / b_z + μ v_h + c,

and λ is fitted by least squares over the flight. λ = 1 for a consistent log. A clock
running s times too slow or fast scales every measured acceleration by 1/s² (λ ≈ 1/s²)
and a position in the wrong unit scales it by that unit (λ ≈ 10⁻³ for mm read as m): the
estimator would then fit the rotor law to a motion the vehicle did not make, and the
inertia (angular acceleration scales the same way) comes out wrong by s², with a small σ.
Such a log is refused (`JobFailedError`, exit 3) when λ lies outside
[1 / `TIME_SCALE_FACTOR`, `TIME_SCALE_FACTOR`] and the flight tilts enough for λ to be
determined (`MIN_TILT_ACCELERATION`); a flight without horizontal manoeuvres is not judged.
The pose is put on a uniform grid per segment and differentiated with the Savitzky–Golay
filter of `mavsysid.estimation.wrench_check`.
"""

from __future__ import annotations

from itertools import pairwise

import numpy as np
from mavsysid.estimation.flight_data import FlightData
from mavsysid.estimation.wrench_check import SMOOTHING_WINDOW
from mavsysid.vehicle.constants import GRAVITY
from mavsysid.vehicle.rotation import continuous_sign, quat_to_matrix
from scipy.signal import savgol_filter

from mavsysid.errors import JobFailedError

__all__ = ["MIN_TILT_ACCELERATION", "TIME_SCALE_FACTOR", "check_kinematics", "tilt_gain"]

#: λ beyond this factor above or below 1 is refused. Why 1.6: a clock 1.27 × off already
#: scales the accelerations (and the inertia estimate) by 1.6 (more than the 50 % an
#: estimate may be off); unmodelled drag, an attitude lagging the position by a few
#: samples and noise move a consistent log's λ by far less (0.96 on the simulated flights
#: of ``bench/fuzz_logs.py``; the ArduCopter SITL and real-log tests are not refused).
TIME_SCALE_FACTOR = 1.6

#: The tilt-predicted horizontal acceleration must vary by at least this RMS, m/s², for λ
#: to be judged: a hovering flight says nothing about its clock this way.
MIN_TILT_ACCELERATION = 0.3

_POLYORDER = 3


def _segment_terms(t: np.ndarray, position: np.ndarray, quaternion: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Measured a_h, tilt-predicted a_h and v_h on a uniform grid, each shape (M, 2)."""
    dt = float(np.median(np.diff(t)))
    window = max(_POLYORDER + 2, round(SMOOTHING_WINDOW / dt))
    window += 1 - window % 2
    grid = t[0] + dt * np.arange(int(np.floor((t[-1] - t[0]) / dt)) + 1)
    if grid.size < 3 * window:
        return None
    q = continuous_sign(quaternion)
    p = np.column_stack([np.interp(grid, t, position[:, i]) for i in range(3)])
    qg = np.column_stack([np.interp(grid, t, q[:, i]) for i in range(4)])
    qg /= np.linalg.norm(qg, axis=1)[:, None]
    b = quat_to_matrix(qg)[:, :, 2]
    a = savgol_filter(p, window, _POLYORDER, deriv=2, delta=dt, axis=0)
    v = savgol_filter(p, window, _POLYORDER, deriv=1, delta=dt, axis=0)
    b = savgol_filter(b, window, _POLYORDER, axis=0)
    upright = b[:, 2] > 0.3  # beyond ~70° of tilt the ratio b_h / b_z means nothing
    predicted = (a[:, 2:3] + GRAVITY) * b[:, :2] / np.where(upright, b[:, 2], 1.0)[:, None]
    cut = slice(window // 2, grid.size - window // 2)  # the filter's edges are extrapolated
    keep = upright[cut]
    return a[cut, :2][keep], predicted[cut][keep], v[cut, :2][keep]


def tilt_gain(flight: FlightData) -> float | None:
    """λ of the module docstring: measured over tilt-predicted horizontal acceleration.

    Returns
    -------
    float or None
        None when the flight does not tilt enough to determine it (or is too short).
    """
    t = np.asarray(flight.t, float)
    bounds = [*flight.segment_starts, t.size]
    parts = [_segment_terms(t[i:j], np.asarray(flight.position[i:j], float),
                            np.asarray(flight.quaternion[i:j], float))
             for i, j in pairwise(bounds) if j - i > 2]
    parts = [x for x in parts if x is not None and x[0].shape[0] > 0]
    if not parts:
        return None
    rows, targets = [], []
    for s, (a, predicted, v) in enumerate(parts):
        for axis in range(2):
            offsets = np.zeros((a.shape[0], 2 * len(parts)))
            offsets[:, 2 * s + axis] = 1.0  # one constant per segment and axis
            rows.append(np.column_stack([predicted[:, axis], v[:, axis], offsets]))
            targets.append(a[:, axis])
    design, target = np.vstack(rows), np.concatenate(targets)
    if not (np.isfinite(design).all() and np.isfinite(target).all()):
        return None
    centred = design[:, 0] - np.mean(design[:, 0])
    if np.sqrt(np.mean(centred**2)) < MIN_TILT_ACCELERATION:
        return None
    solution, *_ = np.linalg.lstsq(design, target, rcond=None)
    return float(solution[0])


def check_kinematics(flight: FlightData) -> None:
    """Refuse, in one line naming the log, a flight whose motion contradicts its attitude.

    Raises
    ------
    JobFailedError
        λ (`tilt_gain`) outside [1 / `TIME_SCALE_FACTOR`, `TIME_SCALE_FACTOR`].
    """
    gain = tilt_gain(flight)
    if gain is None or 1.0 / TIME_SCALE_FACTOR <= gain <= TIME_SCALE_FACTOR:
        return
    raise JobFailedError(
        f"{flight.source}: the horizontal acceleration of the logged position is {gain:.3g} × "
        "what the logged tilt demands (thrust along the body z axis; expected about 1): the "
        "log's clock or position unit is wrong (a clock s × too slow scales it by 1/s²), so "
        "its motion contradicts its attitude and θ cannot be estimated from it")
