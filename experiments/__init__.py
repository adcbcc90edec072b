"""The paper's evaluation, built from the stages and the pipeline (`mavsysid.pipeline`).

`experiment` plans, flies and filters one experiment; `evaluation`, `evaluation_intervals` and
`evaluation_plots` run and summarise many, and `evaluate_job` is the whole evaluation job
(the work of ``mavsysid evaluate``). `baselines` and `data_efficiency` compare planners;
`replanned_flight` re-plans offline with the steps of ``stream --replan-budget``
(`mavsysid.pipeline.replanned_stream`). `bench/` and the command line use these as a library.
"""

__all__: list[str] = []
