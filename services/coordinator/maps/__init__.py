"""Pictures of an exploration's behavioral map: Fig. 2-style cuts and a 3D view."""
