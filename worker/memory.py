"""The memory budget of a job: the worker's pool children are limited to ``Settings.memory_budget_bytes``.

An allocation past the limit raises ``MemoryError`` in the child, and the job fails with
``over_memory_budget`` instead of the kernel's OOM killer taking the process (and the broker
handing the job out again). ``RLIMIT_DATA`` counts the heap and private writable mappings (numpy
arrays, thread stacks) but not reserved-only address space (glibc's per-thread arenas, numba's
and LLVM's reservations), so threads and JIT compilation are unaffected by it.
"""

from __future__ import annotations

import logging
import resource

log = logging.getLogger(__name__)

#: the limit applied (the data segment and private writable mappings)
MEMORY_LIMIT = resource.RLIMIT_DATA


def limit_memory(budget_bytes: int) -> int:
    """Limit this process to ``budget_bytes`` (never above the hard limit it has); the soft limit set."""
    soft, hard = resource.getrlimit(MEMORY_LIMIT)
    limit = budget_bytes if hard == resource.RLIM_INFINITY else min(budget_bytes, hard)
    resource.setrlimit(MEMORY_LIMIT, (limit, hard))
    return limit


def data_bytes() -> int:
    """This process's data size now (``VmData``, bytes): what the limit counts."""
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmData:"):
                return int(line.split()[1]) * 1024
    return 0
