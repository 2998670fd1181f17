"""Dispatch of tiles to workers over zenoh: queryables for lease, results and object meshes,
and a liveliness watcher that puts a lost worker's tiles back in the queue."""
