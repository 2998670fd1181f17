"""Runs it all on one box: the one place that composes the coordinator with the workers.

The `graspscape` console command (`cli`), `graspscape explore` (`explore`), `graspscape map run`
and the in-process run of tests and benchmarks (`run`) live here; `compose` hands the workers'
object preparation to the coordinator. No other module under services/ imports
`graspscape.workers` (tests/test_layers.py checks it).
"""
