"""The worker runtime: simulation processes that pull tiles from the coordinator over zenoh."""
