"""The files the stages exchange, each format read and written in one module.

- `trajectory_file`: the planner's output and the streamer's input (JSON);
- `setpoints_csv`: a trajectory's setpoints sampled at a fixed rate (CSV);
- `flight_dir`: a flight directory ``logs/<flight>/`` and its ``meta.json``;
- `poselog`: the pose log ``pose.csv`` (read strictly, written row by row) and
  motion-capture pose files;
- `flight_log`: a simulated flight's records (``pose.csv``, ``truth.csv``, meta);
- `tlog`, `ulog`, `dataflash`: MAVLink telemetry logs (``.tlog``), PX4 ULog (``.ulg``) and
  ArduPilot DataFlash (``.bin``), each with its autopilot's messages, fields, units and
  motor numbering, read into a `parsed_log.ParsedLog` (their shared types; NED/FRD as the
  logs hold them); `motor_curve`: the motor outputs those logs hold ↔ rotor speed;
  `bounded_parse`: the third-party parsers they call, bounded in size and time;
- `parameter_file`: autopilot parameter files;
- `rerun_file`: Rerun recordings (``.rrd``) written atomically by every stage.

Formats depend on the model (`mavsysid.vehicle`) only, so every stage can read them.
"""

__all__: list[str] = []
