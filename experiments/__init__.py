"""Experiments built from the stages: the paper's evaluation and the end-to-end demo.

`experiment` plans, flies and filters one experiment; `evaluation`, `evaluation_intervals` and
`evaluation_plots` run and summarise many, and `evaluate_job` is the whole evaluation job.
`demo` (with `demo_flight`) plans, flies over MAVLink, estimates and diagnoses on the
simulated vehicle. `bench/` and the command line use these as a library.
"""

__all__: list[str] = []
