"""The numerical core of hairport: pure functions over numpy arrays (no web, no queue)."""
