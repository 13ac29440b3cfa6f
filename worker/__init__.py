"""The job queue (Celery over Redis): tasks that orchestrate solver.pipeline, and the shared storage."""
