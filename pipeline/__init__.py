"""What the commands run: one function per command's work, which the tests call directly.

Each ``mavsysid <command>`` (`mavsysid.cli`) only parses its options, calls one function
here and prints:

- `plan`: `run_plan`, the information-gathering planner (or the random baseline) on a
  checked request, with progress;
- `simulate`: `run_offline_flight`, the offline simulator flying the built-in excitation or
  a trajectory file into a new flight directory;
- `stream`: `run_stream`, one ground-station flight of a trajectory file;
  `replanned_stream`: `run_replanned_stream` (``stream --replan-budget``), the opening
  flown, then the continuation that estimates from the recorded pose and plans the rest;
- `estimate`: `run_estimate`, a log read and θ estimated, refused when implausible;
  `auto_effects`: ``estimate --auto-effects``, θ estimated again with the effects the
  diagnosis names;
- `diagnose`: `run_diagnose`, a log (and an estimate) read and the model diagnosed;
- `demo` (with `demo_flight`): plan, fly over MAVLink against ``mavsysid sim``, estimate and
  diagnose, end to end.

The pipeline sits above the stages (`mavsysid.planner`, `mavsysid.flight`,
`mavsysid.estimation`, `mavsysid.discrepancy`) and below the paper's evaluation
(`mavsysid.experiments`), which flies and estimates the way these jobs do; the
``evaluate`` command's work is the evaluation's own entry point,
`mavsysid.experiments.evaluate_job`.
"""

__all__: list[str] = []
