"""Flying: the offline simulator, the simulated MAVLink vehicle and the ground station.

- `mavsysid.flight.offline`: truth dynamics, controller, truth-side effects, excitation;
- `mavsysid.flight.simvehicle`: a simulated ArduPilot/PX4 vehicle behind a MAVLink endpoint;
- `mavsysid.flight.ground`: the ground station that streams a trajectory file and records the
  flight.

The modules directly here are shared by the last two: the autopilots' flight modes, pymavlink's
set-up, free loopback ports, and keeping the garbage collector out of timed loops. MAVLink is
the only place where NED/FRD frames appear (`mavsysid.vehicle.frames` converts).
"""
