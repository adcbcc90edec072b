"""The files the stages exchange, written and read in one place.

- `trajectory_file`: the planner's output and the streamer's input (JSON);
- `setpoints_csv`: a trajectory's setpoints sampled at a fixed rate (CSV);
- `flight_dir`: a flight directory ``logs/<flight>/`` and its ``meta.json``;
- `poselog`, `poselog_writer`: the pose log ``pose.csv`` (read strictly, written row by row);
- `flight_log`: a simulated or streamed flight's records (``pose.csv``, ``truth.csv``, meta);
- `rerun_file`: Rerun recordings (``.rrd``) written atomically by every stage.

Formats depend on the model (`mavsysid.vehicle`) only, so every stage can read them.
"""

__all__: list[str] = []
