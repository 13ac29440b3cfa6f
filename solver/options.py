"""The options of the two stages, with their defaults and ranges (Table 1, meters): the one place they are defined."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hairport.solver.adaptation.coupled import QP_BACKENDS
from hairport.solver.adaptation.guides import DEFAULT_GUIDES
from hairport.solver.adaptation.multiscale import DEFAULT_CHUNK_PARTICLES
from hairport.solver.baselines import BASELINE_METHODS, parse_method
from hairport.solver.hairline.edit import HairlineEdit
from hairport.solver.model.errors import InputError
from hairport.solver.transfer.anchors import ANCHOR_AUTO, ANCHOR_SIGMA, ANCHORINGS
from hairport.solver.transfer.smoothing import SMOOTHING_EPS

#: the shape-adaptation solvers: guides then independent strands (Sec. 5), or all strands coupled
SOLVER_METHODS = ("multiscale", "global")
METHODS = SOLVER_METHODS + BASELINE_METHODS


#: the solvers stop a strand (or the coupled guides) once an iteration lowers Eq. 1 by less
#: than this fraction (see SolveOptions.energy_tolerance)
ENERGY_TOLERANCE = 1e-3


@dataclass(frozen=True)
class PreprocessOptions:
    """Source-side parameters (Table 1, meters).

    ``anchoring`` (:data:`~hairport.solver.transfer.anchors.ANCHORINGS`) anchors particles
    by the bones (Eq. 2), by the body surface, or ``auto``: by the bones when the source has a
    skeleton with skin weights, else by the surface. An adaptable hairstyle records the one used.
    """

    k: int = 5
    sigma: float = ANCHOR_SIGMA
    guides: int = DEFAULT_GUIDES
    guide_seed: int = 0
    anchoring: str = ANCHOR_AUTO

    def validate(self) -> None:
        if self.anchoring not in ANCHORINGS:
            raise InputError(f"unknown anchoring {self.anchoring!r}; expected one of {', '.join(ANCHORINGS)}",
                             code="bad_option")
        if self.k < 1:
            raise InputError(f"option k must be >= 1, got {self.k}", code="bad_option")
        if self.guides < 1:
            raise InputError(f"option guides must be >= 1, got {self.guides}", code="bad_option")
        if not np.isfinite(self.sigma) or self.sigma < 0:
            raise InputError(f"option sigma must be a finite non-negative number, got {self.sigma}", code="bad_option")


@dataclass(frozen=True)
class RetargetOptions:
    """Target-side parameters (Table 1, meters) and the method.

    ``method`` is ``multiscale`` (Sec. 5), ``global`` (Eq. 1 over all strands coupled) or a
    baseline name, optionally with the ``+pushout`` suffix. ``workers`` processes share the
    multi-scale fine level (``None``: the CPUs available), in chunks of ``chunk_particles``.
    ``qp_backend`` solves the coupled QPs (``global``, and the guides of ``multiscale``): the
    active-set method of :mod:`~hairport.solver.adaptation.active_set` or OSQP. ``hairline`` edits the front
    hairline (Sec. 6; solver methods only).
    """

    method: str = "multiscale"
    alpha: float = 3e3
    beta: float = 1e3
    eps_c: float = 5e-4
    eps_s: float = SMOOTHING_EPS
    max_iterations: int = 30
    step_tolerance: float = 1e-5
    energy_tolerance: float = ENERGY_TOLERANCE
    workers: int | None = None
    chunk_particles: int = DEFAULT_CHUNK_PARTICLES
    qp_backend: str = "active-set"
    hairline: HairlineEdit | None = None

    def validate(self) -> None:
        if self.method not in SOLVER_METHODS:
            try:
                parse_method(self.method)
            except InputError:
                raise InputError(
                    f"unknown method {self.method!r}; expected one of {', '.join(METHODS)} "
                    "(a baseline may carry the suffix +pushout)",
                    code="unknown_method",
                ) from None
        for name in ("alpha", "beta", "eps_c", "eps_s", "step_tolerance", "energy_tolerance"):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise InputError(f"option {name} must be a finite non-negative number, got {value}", code="bad_option")
        if self.max_iterations < 1:
            raise InputError("option max_iterations must be >= 1", code="bad_option")
        if self.qp_backend not in QP_BACKENDS:
            raise InputError(
                f"unknown QP backend {self.qp_backend!r}; expected one of {', '.join(QP_BACKENDS)}", code="bad_option"
            )
        if self.workers is not None and self.workers < 1:
            raise InputError("option workers must be >= 1", code="bad_option")
        if self.chunk_particles < 1:
            raise InputError("option chunk_particles must be >= 1", code="bad_option")
        if self.hairline is not None:
            if self.method not in SOLVER_METHODS:
                raise InputError(
                    f"a hairline edit needs the method multiscale or global, not the baseline {self.method!r}",
                    code="bad_option",
                )
            self.hairline.validate()
