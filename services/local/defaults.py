"""Defaults of `graspscape explore`, importable without the store or zenoh (for --help).

20° between approach directions and start gaps 1, 2, 3 cm make 318 poses: a coarse first map
that the 2-core development machine evaluates in about two minutes on a built-in object.
"""

DEFAULT_DTHETA_DEG = 20.0
DEFAULT_R = (0.01, 0.03, 0.01)  # r_min, r_max, dr in metres
DEFAULT_LEVELS = 1  # one halving of the grid at manifold borders
