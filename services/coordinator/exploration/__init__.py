"""Explorations: submission, tiles of work, progress, results queries."""
