"""The memory a retarget needs, estimated from declared counts before anything is allocated.

Readers check a file's declared particle count against a budget (``ReadLimits.memory_budget_bytes``)
before they build arrays; the service checks it at upload, and the worker again before a solve
(:func:`check_memory`). What cannot fit is refused with code ``over_memory_budget``.
"""

from __future__ import annotations

from hairport.solver.model.errors import InputError

#: peak resident bytes per particle of preprocessing plus a multi-scale retarget, with the
#: default k. Measured with ``bench/table4.py`` (MakeHuman average female -> heavy male, "long"
#: grooms, 300 guides, k = 5, peak = the retarget process plus its largest fine-level worker):
#: 369 MB at 10^5 particles and 2,726 MB at 10^6, i.e. 2,619 B per added particle over a
#: ~107 MB base; rounded up to 3,000 B to cover the base at 10^6 and the toy-to-MakeHuman
#: spread of body sizes.
BYTES_PER_PARTICLE = 3_000
#: the k the figure above was measured with
MEASURED_K = 5
#: bytes per particle per neighbour beyond MEASURED_K: the two kNN sets (Eq. 8-9) keep an
#: int64 index and a float64 weight per neighbour (16 B each, x2 sets), doubled for the
#: temporaries of the query; counted from the arrays, not measured
BYTES_PER_NEIGHBOUR = 64
#: the code of an input whose estimated need is above the budget
OVER_MEMORY_BUDGET = "over_memory_budget"


def estimate_bytes(particles: int, k: int = MEASURED_K) -> int:
    """Peak bytes a job on ``particles`` particles with ``k`` neighbours is expected to need."""
    return int(particles) * (BYTES_PER_PARTICLE + max(0, int(k) - MEASURED_K) * BYTES_PER_NEIGHBOUR)


def check_memory(particles: int, budget_bytes: int | None, k: int = MEASURED_K, source: str | None = None) -> None:
    """Refuse (``over_memory_budget``) a job whose estimated need is above ``budget_bytes`` (None: no budget)."""
    if budget_bytes is None:
        return
    need = estimate_bytes(particles, k)
    if need > budget_bytes:
        raise InputError(
            f"{particles:,} particles need about {need / 1024**3:.1f} GiB "
            f"({estimate_bytes(1, k):,} B per particle), above this deployment's memory budget of "
            f"{budget_bytes / 1024**3:.1f} GiB (raise it with HAIRPORT_MEMORY_BUDGET_BYTES)",
            source, OVER_MEMORY_BUDGET,
        )
