"""Moved to graspscape.services.coordinator.mapspace.lattice (the map's vocabulary, below both
exploration/ and manifolds/); this path is that very module, for the callers that still
import it from here."""

import sys

from graspscape.services.coordinator.mapspace import lattice as _moved

sys.modules[__name__] = _moved
