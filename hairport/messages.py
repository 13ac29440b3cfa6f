"""What an error message may show a caller: bounded, printable, and without storage names.

Error details echo what the caller sent (an id, a file's own text) and what a reader said about
a stored file; :func:`safe_detail` is the one place that bounds them (a 1 MB id gives a short
404, not a 1 MB one), drops control characters and NUL bytes, and hides content addresses
(blob names are SHA-256 digests) so no message reveals how storage names its files.
"""

from __future__ import annotations

import re

#: characters of an error detail kept; the rest is cut with an ellipsis
MAX_DETAIL_CHARS = 300
#: what replaces a content address (a blob's SHA-256, alone or in a file name) in a message
STORED_FILE = "<stored file>"

_CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f]+")
_BLOB_NAME = re.compile(r"(?:\S*/)?[0-9a-f]{64}(?:\.[A-Za-z0-9]+)?")


def safe_detail(text: object, limit: int = MAX_DETAIL_CHARS) -> str:
    """``text`` as one printable line of at most ``limit`` characters, with blob names hidden."""
    # cut first: the patterns then run on a few hundred characters whatever the caller sent
    text = _CONTROL.sub(" ", str(text)[: 2 * limit])
    text = _BLOB_NAME.sub(STORED_FILE, text)
    return text if len(text) <= limit else text[: limit - 1] + "\u2026"
