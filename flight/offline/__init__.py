"""The offline simulator: a trajectory flown as fast as the computer allows, no MAVLink.

- `simulator`: `Simulator` flies a trajectory and, given a flight directory, writes
  ``pose.csv``, ``truth.csv`` and ``meta.json`` into it;
- `truth_step`, `sensor_noise`: the truth's RK4 step (motor lag, effects) and the
  motion-capture and rotor-speed noise, shared with `mavsysid.flight.simvehicle`, which
  flies the same physics behind a MAVLink endpoint;
- `controller`: the geometric controller on the config's nominal θ;
- `effects`: truth-side effects (what the world does that the model may not know);
- `sensor_path`, `log_timing`: a pose from an on-board estimator (lagged, smoothed,
  correlated noise) and a logger's stamp jitter and dropped samples, to fly a vehicle
  the way real small vehicles are logged;
- `excitation`: the built-in excitation trajectory.
- `phased_flight`: take-off, a calibration part and landing as one trajectory;
- `autopilot_log`, `ardupilot_log`, `px4_log`: a simulated flight written as ArduPilot and PX4
  log it (which messages, at which rates, mode changes, their motor numbering), encoded by
  `mavsysid.formats.dataflash` and `mavsysid.formats.ulog`.
"""


from __future__ import annotations

from mavsysid.flight.offline.controller import ControllerGains, GeometricController
from mavsysid.flight.offline.effects import ConstantWrench, ProcessNoise, TruthEffect
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.flight.offline.simulator import SimulationResult, SimulationSettings, Simulator

__all__ = [
    "ConstantWrench",
    "ControllerGains",
    "ExcitationSpec",
    "GeometricController",
    "ProcessNoise",
    "SimulationResult",
    "SimulationSettings",
    "Simulator",
    "TruthEffect",
    "excitation_trajectory",
]
