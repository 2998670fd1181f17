"""The coordinator: REST API, store and tile queue of explorations (docs/design/store.md)."""
