"""The deployment id: written once in the storage (``deployment.json``), read by API and workers.

A deployment is one storage (a folder, or an object store that hosts share: then its id is derived
from the store's URL and endpoint, :func:`deployment_for`) and the processes that share it. Its id names its queues
(:func:`queue_name`) and travels in every task, so that a worker started on another folder (a
relative path resolved elsewhere, a typo, a second deployment on the same Redis database) never
takes this deployment's tasks and says so, instead of finding no records and reporting success.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import secrets
from pathlib import Path

from .layout import _create_temp, _unlink, check_name

DEPLOYMENT_FILE = "deployment.json"
#: random bytes of a new deployment id (hex-encoded: twice as many characters)
DEPLOYMENT_ID_BYTES = 6
#: the standard variable naming an S3 endpoint (a deployment on another endpoint is another deployment)
AWS_ENDPOINT_VARIABLE = "AWS_ENDPOINT_URL"
#: every queue and control name of hairport starts with this
QUEUE_PREFIX = "hairport"


def deployment_id(root: Path, *, create: bool = True) -> str:
    """The id of the deployment whose storage is ``root``; made (once, race-free between processes and
    hosts) when ``create`` and the folder has none. ``FileNotFoundError`` when it has none and not ``create``."""
    path = Path(root) / DEPLOYMENT_FILE
    try:
        return _read(path)
    except FileNotFoundError:
        if not create:
            raise
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, temp = _create_temp(path.parent, "deployment-")
    with os.fdopen(fd, "w") as handle:
        json.dump({"id": secrets.token_hex(DEPLOYMENT_ID_BYTES), "storage": str(path.parent)}, handle)
        handle.flush()
        os.fsync(handle.fileno())
    try:
        # link() fails if the name exists: the first process to get there wins, the others read its id
        with contextlib.suppress(FileExistsError):
            os.link(temp, path)
    finally:
        _unlink(temp)
    return _read(path)


def deployment_for(settings) -> str:
    """The deployment id of a process with these settings (:class:`hairport.settings.Settings`): with an object
    store (``storage_url``), derived from its URL and endpoint, so that every host configured alike agrees
    without writing anything; else the storage folder's (:func:`deployment_id`)."""
    if not settings.storage_url:
        return deployment_id(settings.storage_dir)
    endpoint = settings.s3_endpoint_url or os.environ.get(AWS_ENDPOINT_VARIABLE, "")
    name = f"{settings.storage_url.rstrip('/')}|{endpoint.rstrip('/')}"
    return hashlib.blake2b(name.encode(), digest_size=DEPLOYMENT_ID_BYTES).hexdigest()


def queue_name(deployment: str, queue: str) -> str:
    """The broker name of one of a deployment's queues: ``hairport.<deployment>.<queue>``."""
    return f"{QUEUE_PREFIX}.{check_name(deployment, 'deployment id')}.{check_name(queue, 'queue')}"


def _read(path: Path) -> str:
    return check_name(json.loads(path.read_text())["id"], "deployment id")
