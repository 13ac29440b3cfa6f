"""What both QP backends share: solve options, cancellation, the merit penalty and the damping rule."""

from __future__ import annotations

from dataclasses import dataclass

#: the l1 penalty on constraint violation in the merit function is this times the largest multiplier
MERIT_PENALTY_FACTOR = 2.0
#: step halvings tried before the shortest step is taken anyway
MAX_BACKTRACKS = 6


#: radial damping of Eq. 7's curvature model (see energies.shape_blocks): start, bounds, factor
INITIAL_RADIAL_DAMPING = 1.0
MIN_RADIAL_DAMPING = 1e-4
MAX_RADIAL_DAMPING = 1.0
DAMPING_FACTOR = 4.0


class Cancelled(RuntimeError):
    """The caller asked the solve to stop."""


@dataclass(frozen=True)
class SolveOptions:
    """Settings of the outer loop and of OSQP.

    Attributes
    ----------
    eps_c : float
        Clearance of Eq. 13 (m).
    max_iterations : int
        Cap on outer iterations.
    step_tolerance : float
        Converged when no particle moves more than this (m) in an iteration ...
    clearance_tolerance : float
        ... and no free particle is closer than ``eps_c - clearance_tolerance`` (m).
    energy_tolerance : float
        The active-set solver (:mod:`.strand_solver`) also stops a strand (or the coupled
        hairstyle) whose Eq. 1 merit fell by less than this fraction in an iteration, with
        the clearance kept: the tail of the nonconvex loop creeps by micrometres per
        iteration without visible change. 0 disables the test.
    osqp_eps_abs, osqp_eps_rel : float
        OSQP's stopping tolerances (meters for the constraints).
    osqp_max_iter : int
    """

    eps_c: float = 5e-4
    max_iterations: int = 30
    step_tolerance: float = 1e-5
    clearance_tolerance: float = 1e-5
    energy_tolerance: float = 0.0
    osqp_eps_abs: float = 1e-7
    osqp_eps_rel: float = 1e-7
    osqp_max_iter: int = 50_000
