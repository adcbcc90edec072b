"""Experiments built from the stages: the paper's evaluation and the end-to-end demo.

`experiment` plans, flies and filters one experiment; `evaluation`, `evaluation_intervals` and
`evaluation_plots` run and summarise many. `bench/` and the command line use these as a library.
"""
