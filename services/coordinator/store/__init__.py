"""The coordinator store: ORM models, the tile queue, result ingest, worker registry."""
