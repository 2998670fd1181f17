"""Objects to be grasped: upload, mesh validation, storage."""
