"""The job queue (Celery over Redis): the app, the queue the API sends through, the job bodies and
the tasks that wrap them. The folder ``worker/`` is installed as ``hairport.worker``."""
