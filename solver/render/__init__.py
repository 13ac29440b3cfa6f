"""Pictures of results (PIL); optional, never imported by the pipeline."""
