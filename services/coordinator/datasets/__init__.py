"""Grasp datasets other tools read: GraspGen's JSON and ACRONYM-style HDF5
(docs/reference/formats.md).

`rows.py` streams an exploration's poses with the gripper transform of each, `transforms.py`
makes those transforms, `graspgen.py` and `acronym.py` write the two layouts.
"""
