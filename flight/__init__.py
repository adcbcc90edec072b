"""Flying: the position controller, the offline simulator and flight recording.

MAVLink (the simulated vehicle endpoint and the setpoint streamer) lives here too, and
is the only place where NED/FRD frames appear.
"""

from __future__ import annotations

from flight.controller import ControllerGains, GeometricController
from flight.effects import ConstantWrench, ProcessNoise, TruthEffect
from flight.excitation import ExcitationSpec, excitation_trajectory
from flight.simulator import SimulationResult, SimulationSettings, Simulator

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
