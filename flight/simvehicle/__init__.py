"""The simulated MAVLink vehicle behind ``mavsysid sim``.

It speaks MAVLink 2 like ArduPilot Copter or PX4 (heartbeat, telemetry, parameters, modes,
arming, takeoff, landing, guided/offboard setpoints) and flies the offline simulator's
physics (`mavsysid.flight.offline.truth_step`, its controller and effects) on the true θ,
in sim-time ticks paced by its own clock (`clock`). `endpoint.SimEndpoint` ties link,
autopilot, physics and telemetry together.
"""

__all__: list[str] = []
