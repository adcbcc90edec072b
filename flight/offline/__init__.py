"""The offline simulator: truth dynamics, the geometric controller, truth-side effects and the
built-in excitation trajectory. No MAVLink; `mavsysid.flight.simvehicle` runs the same physics
behind a MAVLink endpoint.
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
