"""The map's vocabulary, below both exploration/ and manifolds/: the lattice and its points
(`lattice.py`), the stored pose and the pose shape of the API (`pose.py`), stored poses by
lattice point (`samples.py`), the stored spec (`specs.py`), local maxima (`maxima.py`).
It imports neither exploration/ nor manifolds/ (tests/test_layers.py)."""
