"""The ground station behind ``mavsysid stream``: fly a trajectory file and record the flight.

`streamer.fly` runs the whole sequence over a `mavlink_link.MavlinkLink`: pre-flight checks
(`preflight`), take-off, setpoints at a fixed rate with their guards (`stream_control`,
`setpoints`), landing. `stream_session` makes the flight directory and its ``meta.json``;
the link records ``flight.tlog`` (`mavsysid.formats.tlog`, stamped by `link_clock`) and
`telemetry_recorder` ``pose.csv``, each row on disk as it arrives.
"""

__all__: list[str] = []
