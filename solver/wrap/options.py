"""Settings of the wrap: the stiffness schedule, the correspondence rejections, the stopping rules.

The defaults, measured with ``bench/wrap.py`` on average-female wrapped onto the other
MakeHuman presets remeshed to 20k vertices: the first, stiff steps settle the global fit (a
stiffer start, alpha 1000, or a softer one, 50, end within 0.1 mm of each other on the
scalp); the soft ones bring the residual down to 0.25-0.45 mm mean. Two more steps, alpha
0.2 and 0.05, take it to 0.15-0.3 mm but move no vertex nearer its truth and cost 35 % more
time (a 20k head: 3.6 s instead of 2.7 s), so they are left to the caller. Ten correspondence
updates per step, where five or six cost 0.1-0.5 mm of scalp accuracy.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class WrapOptions:
    """How :func:`~hairport.solver.wrap.wrap_body` fits the source onto the target.

    Attributes
    ----------
    stiffness : tuple of float
        Amberg's ``alpha``, one per step, stiff to soft (normalised coordinates: the region's
        RMS radius is 1).
    landmark_weights : tuple of float
        The weight per step of landmarks the caller gives (the last value repeats over longer
        schedules): all landmarks together weigh this many times the data term of the whole
        fitted patch (Amberg's ``beta^2`` is this times the patch's vertex count over the
        landmark count); 0 ignores the landmarks in that step. Held to the end, so that each
        lands within 0.1 mm of its target: on the MakeHuman presets (average female onto
        three others remeshed to 20k vertices, a short groom), four landmarks held so brought
        the result from 3.1-5.5 mm to 1.6-2.7 mm (mean) of the same-topology retarget,
        released after the third step only to 3.1-4.4 mm, 6-7 mm off their targets.
    derived_landmark_weights : tuple of float
        The same for landmarks derived from the two heads (``derive_landmarks``): uncertain
        along flat stretches, they steer the stiff first steps only.
    gamma : float
        Weight of translation against the linear part of the transforms in the stiffness term.
    max_distance_m : float
        Correspondences farther than this (m) get no data term.
    max_normal_angle_deg : float
        Nor those whose source and target normals differ by more than this (degrees).
    inner_iterations : int
        Correspondence updates per stiffness step, at most.
    tolerance_m : float
        A step ends when no vertex moved farther than this in an update (m); on the MakeHuman
        heads most steps use all their updates (the last ones move 0.1-1 mm, along the surface).
    start_iterations : int
        Similarity ICP iterations of the start.
    derive_landmarks : bool
        Without landmarks from the caller, derive a few from the two heads
        (:func:`~hairport.solver.wrap.landmarks.head_landmarks`). Off by default: on the
        MakeHuman presets they moved the scalp 0.1-1.4 mm farther from the truth (the extreme
        point of a flat stretch, the top of the skull, is centimetres off along it).
    refuse : bool
        Raise ``wrap_failed`` when the residual shows the target's shape was not reached
        (:func:`~hairport.solver.wrap.result.check_wrap`).
    """

    stiffness: tuple[float, ...] = (50.0, 20.0, 10.0, 5.0, 2.0, 1.0, 0.5)
    landmark_weights: tuple[float, ...] = (1.0, 0.5, 0.3)
    derived_landmark_weights: tuple[float, ...] = (1.0, 0.5, 0.2, 0.0)
    gamma: float = 1.0
    max_distance_m: float = 0.05
    max_normal_angle_deg: float = 60.0
    inner_iterations: int = 10
    tolerance_m: float = 2e-5
    start_iterations: int = 20
    derive_landmarks: bool = False
    refuse: bool = True

    def landmark_weight(self, step: int) -> float:
        """The landmarks' weight in stiffness step ``step`` (see ``landmark_weights``)."""
        weights = self.landmark_weights or (0.0,)
        return float(weights[min(step, len(weights) - 1)])
