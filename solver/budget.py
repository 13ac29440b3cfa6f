"""The memory a retarget needs, estimated from declared counts before anything is allocated.

Readers check a file's declared particle count against a budget (``ReadLimits.memory_budget_bytes``)
before they build arrays; the service checks it at upload, and the worker again before a solve
(:func:`check_memory`). What cannot fit is refused with code ``over_memory_budget``.
"""

from __future__ import annotations

from hairport.solver.model.errors import InputError

#: peak resident bytes per particle of preprocessing plus a multi-scale retarget, with the
#: default k, counting every process. Measured with ``bench/preprocess.py --solve`` on the
#: solver as merged for issue 13 (the fine level on numba's threads in the retarget's process,
#: the default), MakeHuman average female -> heavy male, "long" groom, 300 guides, k = 5:
#: 798 MB at 10^6 particles and 1,649 MB at 3x10^6 (550 B per particle; 475 above the 224 MB
#: base of interpreter, libraries, compiled kernels and bodies); ``bench/table4.py`` measured
#: 906 B per particle at 10^6. The base's share per particle falls as grooms grow, so 10^6 is
#: where the figure is tightest: 906 B rounded up by 21 % to 1,100 B (the margin covers the
#: spread of body sizes and strand layouts). Fine-level worker processes (``workers`` > 1) add
#: about 0.5 GB each, not covered here. Before issue 13 it was 3,000 B (2,726 MB at 10^6).
BYTES_PER_PARTICLE = 1_100
#: the k the figure above was measured with
MEASURED_K = 5
#: bytes per particle per neighbour beyond MEASURED_K: the two kNN sets kept per particle (the
#: fine level's, Eq. 14, and the metrics' over all strands, Eq. 8-9) hold an int32 index and
#: a float64 weight per neighbour (12 B each, x2 sets), doubled for the temporaries of the
#: query; counted from the arrays, not measured
BYTES_PER_NEIGHBOUR = 48
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
