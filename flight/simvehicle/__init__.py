"""The simulated MAVLink vehicle behind ``mavsysid sim``.

It speaks MAVLink 2 like ArduPilot Copter or PX4 (heartbeat, telemetry, parameters, modes,
arming, takeoff, landing, guided/offboard setpoints) and flies the offline simulator's physics
(`mavsysid.flight.offline`) on the true θ, paced by its own clock. `endpoint.SimEndpoint` ties
link, autopilot, physics and telemetry together.
"""
