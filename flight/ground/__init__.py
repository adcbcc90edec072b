"""The ground station behind ``mavsysid stream``: fly a trajectory file and record the flight.

`streamer.fly` runs the whole sequence over a `mavlink_link.MavlinkLink`: pre-flight checks,
take-off, setpoints at a fixed rate with their guards, landing; `stream_session` and
`telemetry_recorder` put ``flight.tlog``, ``pose.csv`` and ``meta.json`` on disk as they arrive.
"""
