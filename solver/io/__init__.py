"""File formats: hair and characters, one module per format behind a registry."""
