"""Behavioral manifolds: grouping poses by the grasp they lead to, and the stored summaries."""
