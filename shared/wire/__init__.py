"""The coordinator ↔ worker protocol over zenoh: key expressions, messages, encode/decode."""
