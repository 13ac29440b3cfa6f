"""The HTTP API (FastAPI): routes, schemas, authentication, problem responses."""
