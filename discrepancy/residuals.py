"""The model replayed along a flight and compared with the measurement, in acceleration space.

The *equation-error residual* of a flight, per sample and axis, is

    r = [f_meas − F_B/m,  ω̇_meas − J⁻¹(M_B − ω × J ω)]       (paper Eqs. newton, euler)

with f_meas = Rᵀ(a − g) the body-frame specific force (m/s²) and ω̇_meas the angular
acceleration (rad/s²), both derived from the pose log by a Savitzky–Golay smoother
(`smooth_pose`), and F_B, M_B the model's wrench (paper Eq. drag plus the given
`ModelEffect` wrenches) at the smoothed state and the logged rotor speeds. The law-level
pieces (smoothing, the model's accelerations, the common smoother) are the estimator's
(`mavsysid.estimation.signals`, re-exported here); this module adds the diagnosis'
problem: one flight, resampled, with model effects.

Effects enter through their catalogue channels: ``corrected_pose`` changes the measured
side (marker and CoG offsets, pose delay), ``acting_rotor_speeds`` the speeds the model
uses (motor lag), ``wrench`` the model's force and torque. The residual is linear in most
effect parameters, which is what `mavsysid.discrepancy.candidates` exploits.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np
from mavsysid.discrepancy.resample import Resampling
from mavsysid.estimation import (
    AXIS_NAMES,
    AXIS_UNITS,
    FlightData,
    SmoothedPose,
    SmootherSettings,
    acceleration_kernel,
    consistent_accelerations,
    model_accelerations,
    noise_gain,
    smooth_pose,
    uniform_step,
)
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.model_effects import ModelEffect

#: Smoothed poses kept (each a few MB at most): the pose effects of one selection step.
_SMOOTHED_CACHE = 32

__all__ = [
    "AXIS_NAMES",
    "AXIS_UNITS",
    "ResidualProblem",
    "SmoothedPose",
    "SmootherSettings",
    "acceleration_kernel",
    "model_accelerations",
    "noise_gain",
    "smooth_pose",
]


@dataclass(frozen=True)
class ResidualProblem:
    """One flight, a vehicle and its identified θ: the residual as a function of effects.

    Attributes
    ----------
    flight : FlightData
    config : VehicleConfig
    theta : ndarray, shape (6,)
        The identified θ the model is replayed with.
    settings : SmootherSettings
    known_effects : tuple of ModelEffect
        Effects already part of the model (a config's ``[effects.*]``).
    resampling : Resampling, optional
        How ``flight`` was put on its uniform grid (`mavsysid.discrepancy.resample`);
        None: ``flight`` must be uniformly sampled.
    theta_free : ndarray of bool, shape (6,), optional
        The entries of θ the fits may move (all when None); the others are held where
        they are (a parameter the flight does not determine stays at its prior).
    smoothed : dict
        The pose smoothed per set of pose-channel effects (their names and values), shared
        by the copies `dataclasses.replace` makes for other θ: the selection re-evaluates
        the residual hundreds of times with the same pose effects, and smoothing is most
        of an evaluation's cost.
    """

    flight: FlightData
    config: VehicleConfig
    theta: np.ndarray
    settings: SmootherSettings = field(default_factory=SmootherSettings)
    known_effects: tuple[ModelEffect, ...] = ()
    resampling: Resampling | None = None
    theta_free: np.ndarray | None = field(default=None, compare=False)
    smoothed: dict = field(default_factory=dict, compare=False, repr=False)

    def __post_init__(self) -> None:
        _ = self.dt  # refuses a log sampled at a non-uniform rate

    # Caches on a frozen dataclass (cached_property writes the instance __dict__): each
    # value is a pure function of the fields, and every residual evaluation reads them.
    @cached_property
    def dt(self) -> float:
        """Sample time, s."""
        if self.resampling is not None:
            return self.resampling.dt
        return uniform_step(self.flight.t, self.flight.source)

    @property
    def stamp_dt(self) -> float:
        """The log's own sample interval, s (before any averaging of `resampling`)."""
        return self.resampling.log_dt if self.resampling is not None else self.dt

    @property
    def window_samples(self) -> int:
        """Smoother window, samples."""
        return self.settings.samples(self.dt)

    @property
    def block(self) -> int:
        """Correlation length of the residual, samples: one effective sample per block."""
        if self.resampling is None:
            return self.window_samples
        return self.resampling.block(self.window_samples)

    def keep(self) -> np.ndarray:
        """Boolean mask of the samples used (the ends and gaps trimmed), shape (N,)."""
        t = self.flight.t
        edge = max(self.settings.trim, self.window_samples * self.dt)
        keep = (t >= t[0] + edge) & (t <= t[-1] - edge)
        if self.resampling is not None:
            keep &= self.resampling.usable(int(np.ceil(edge / self.dt)))
        return keep

    def evaluate(self, effects: Sequence[ModelEffect] = (), theta: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray, SmoothedPose]:
        """Measured and model accelerations with ``effects`` added to the known ones.

        Returns
        -------
        measured, model : ndarray, shape (N, 6)
            [f_B, ω̇] from the pose, and the model's [F_B/m, ω̇] smoothed the same way.
        pose : SmoothedPose
        """
        theta = self.theta if theta is None else np.asarray(theta, float)
        all_effects = (*self.known_effects, *effects)
        fl = self.flight
        t, p, q = fl.t, fl.position, fl.quaternion
        n = np.asarray(fl.rotor_speeds, float)
        for effect in all_effects:
            if "rotor_speeds" in effect.channels:
                n = effect.acting_rotor_speeds(fl.t, n)
        pose_effects = [e for e in all_effects if "pose" in e.channels]
        for effect in pose_effects:
            t, p, q = effect.corrected_pose(t, p, q)
        if t is not fl.t:
            # A delayed pose belongs to earlier times: the rotor speeds are read there.
            n = np.column_stack([np.interp(t, fl.t, n[:, i]) for i in range(n.shape[1])])
        key = tuple((e.name, e.values.tobytes()) for e in pose_effects)
        if key not in self.smoothed:
            if len(self.smoothed) >= _SMOOTHED_CACHE:
                # The oldest entry that is not the log itself (key ()) goes.
                self.smoothed.pop(next(k for k in self.smoothed if k))
            self.smoothed[key] = self._smooth(t, p, q)
        pose, inputs = self.smoothed[key]
        model = model_accelerations(inputs, n, theta, self.config, all_effects)
        measured, model = consistent_accelerations(pose, inputs, model, self.settings,
                                                  self.dt)
        return measured, model, pose

    def _smooth(self, t: np.ndarray, p: np.ndarray, q: np.ndarray
                ) -> tuple[SmoothedPose, SmoothedPose]:
        light = replace(self.settings, window=self.settings.input_window)
        source = self.flight.source
        return (smooth_pose(t, p, q, self.settings, source),
                smooth_pose(t, p, q, light, source))

    def residual(self, effects: Sequence[ModelEffect] = (), theta: np.ndarray | None = None
                 ) -> np.ndarray:
        """measured − model, shape (N, 6) (all samples; use `keep` to drop the edges)."""
        measured, model, _ = self.evaluate(effects, theta)
        return measured - model
