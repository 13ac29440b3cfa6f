"""The HTTP API (FastAPI): routers, service functions, schemas, authentication, problem responses.

The folder ``service/`` is installed as ``hairport.service``; it reaches the worker only through
:mod:`hairport.worker.queue`."""
