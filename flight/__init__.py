"""Flying: the offline simulator, the simulated MAVLink vehicle and the ground station.

- `mavsysid.flight.offline`: truth dynamics, controller, truth-side effects, excitation; no
  MAVLink, no clock;
- `mavsysid.flight.simvehicle`: a simulated ArduPilot/PX4 vehicle behind a MAVLink endpoint,
  flying the offline simulator's physics in (scaled) real time;
- `mavsysid.flight.ground`: the ground station that streams a trajectory file to a vehicle
  and records the flight.

The modules directly here are utilities: `autopilot_modes` (the autopilots' flight modes),
`mavlink_setup` (pymavlink's dialect, connection strings, signing key, the ground
station's MAVLink identity) and `gc_freeze` (the garbage collector out of timed loops)
serve both the simulated vehicle and the ground station; `loopback_ports` finds free
127.0.0.1 ports for the demo, the benches and the tests. Within flight, NED/FRD frames
appear only on the MAVLink side (`mavsysid.vehicle.frames` converts).
"""

__all__: list[str] = []
