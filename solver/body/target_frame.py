"""The units and axes of a target of another topology, found by fitting the source's head to it.

A target of the source's topology takes its units and axes from the source vertex by vertex
(:func:`~hairport.solver.body.orientation.relative_axes`). A target of another topology has no
such correspondence, and no hair to hang (the sources' own inference,
:func:`~hairport.solver.body.orientation.infer_axes`, reads the strands). What it shares with
the source is a head: every candidate frame (the 24 proper rotations that take one axis to up
and another to front, times the units not given) is tried by placing the source's head, crown
on crown, on the target read in that frame, and measuring how far the head's points are from
the target's surface. The frame of the nearest fit wins. A wrong up axis leaves the head in the
air or in the chest (decimetres), a wrong unit leaves it ten times too small or large, and a head
turned around puts the nose into the back of the skull (centimetres); heads of two people of the
same frame differ by millimetres.

The fit only chooses the frame; the wrap (:mod:`hairport.solver.wrap`) then aligns the two bodies,
and refuses a target that holds no head (``wrap_failed``). The fit does not: measured with the
average female's head, the five other MakeHuman presets remeshed to 20k vertices (bodies, heads
cut at the neck, busts; in mm with Z up and in cm with -X up) are all read in their true frame,
which fits at 3.5-7.4 mm where the runner-up frame scores 6.6-11.2 mm (the heavy male's head, the
narrowest: 7.4 against 8.0 mm), while a cylinder of a head's size fits at 11.8 mm, a sphere or a
torus at 15-16 mm and a box at 21 mm: too close to tell a head by this score alone, far enough
apart to choose among a head's frames (2 s at most for a 20k-vertex body, 96 frames x 7 sizes).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hairport.solver.body.head_frame import mesh_head_frame
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.model.character import Character
from hairport.solver.model.frame import AXIS_VECTORS, InputFrame, parse_axis
from hairport.solver.model.units import METERS_PER_UNIT, UNITS

#: points of the source's head the fit measures (an even subset: the score is a mean)
HEAD_SAMPLE = 1_000
#: the crown of a body read in a frame: the mean of its vertices this high share of the way up
CROWN_SHARE = 0.005
#: a head point farther than this (m) from the target counts as this far (a cut neck, an open
#: mouth or a missing ear must not outweigh the head's shape)
DISTANCE_CAP_M = 0.05
#: the head's sizes tried about its crown in every frame: heads of two adults differ by up to a
#: fifth, a child's by a quarter, and a wrong frame can fit a head of the wrong size as closely as
#: the right frame fits one of the source's size
HEAD_SCALES = (0.75, 0.85, 0.95, 1.05, 1.15, 1.25, 1.35)
#: the fit is confident when the second-best frame's score is at least this many times the best's
CONFIDENT_RATIO = 1.5


@dataclass(frozen=True)
class FrameFit:
    """The frame chosen for a target and how clearly.

    Attributes
    ----------
    frame : InputFrame
    score_m : float
        Mean capped distance (m) of the source's head points to the target read in ``frame``.
    runner_up_m : float
        The next best frame's score (inf when only one was tried).
    """

    frame: InputFrame
    score_m: float
    runner_up_m: float

    @property
    def confidence(self) -> float:
        """1 - best / runner-up: 0 when two frames fit alike, near 1 when one alone fits."""
        return 0.0 if not np.isfinite(self.score_m) else float(1.0 - self.score_m / max(self.runner_up_m, 1e-12))

    @property
    def confident(self) -> bool:
        return self.runner_up_m >= CONFIDENT_RATIO * self.score_m


def frame_candidates(units: str | None, up: str | None, front: str | None) -> list[InputFrame]:
    """Every frame that keeps the given parts: the axis pairs (up, front perpendicular to it) and the units."""
    ups = [up] if up is not None else list(AXIS_VECTORS)
    frames = []
    for candidate_up in ups:
        fronts = [front] if front is not None else [axis for axis, vector in AXIS_VECTORS.items()
                                                    if abs(float(vector @ AXIS_VECTORS[candidate_up])) < 0.5]
        for candidate_front in fronts:
            for candidate_units in ([units] if units is not None else list(UNITS)):
                frames.append(InputFrame(candidate_units, candidate_up, candidate_front))
    return frames


def head_sample(source: Character) -> np.ndarray:
    """(n, 3) float64: an even subset of the source's head vertices (canonical, meters), at most :data:`HEAD_SAMPLE`."""
    head = source.vertices[mesh_head_frame(source).head_vertices]
    return head[:: max(1, len(head) // HEAD_SAMPLE)]


def crown(points: np.ndarray) -> np.ndarray:
    """(3,) the mean of the highest :data:`CROWN_SHARE` of ``points (n, 3)`` along canonical +Y."""
    count = max(1, int(np.ceil(CROWN_SHARE * len(points))))
    top = np.argpartition(-points[:, 1], count - 1)[:count]
    return points[top].mean(axis=0)


def fit_score(head: np.ndarray, head_crown: np.ndarray, target_crown: np.ndarray, query: MeshQuery,
              frame: InputFrame, size: float = 1.0) -> float:
    """Mean capped distance (m) of the head points ``(n, 3)``, scaled by ``size`` about its crown and put on the
    target's crown ``(3,)`` (canonical axes, the file's units), to the target read in ``frame``.

    The head is moved into the target's file coordinates (one query structure serves every frame).
    """
    scale = METERS_PER_UNIT[frame.units]
    placed = (size * (head - head_crown) / scale + target_crown) @ frame.rotation
    distance = np.abs(query.signed_distance(placed).distance) * scale
    return float(np.mean(np.minimum(distance, DISTANCE_CAP_M)))


def fit_target_frame(source: Character, target: Character, units: str | None = None, up: str | None = None,
                     front: str | None = None) -> FrameFit:
    """The frame (units, up, front) of ``target`` in which the source's head, at its best size, fits it best.

    Parameters
    ----------
    source : Character
        Canonical frame, meters.
    target : Character
        In its file's coordinates.
    units, up, front : str, optional
        The parts already known (given or stated by the file); the rest are fitted.
    """
    up = None if up is None else parse_axis(up, "up axis")
    front = None if front is None else parse_axis(front, "front axis")
    head = head_sample(source)
    head_crown = crown(head)
    query = MeshQuery(target.vertices, target.faces)
    crowns = {}  # the target's crown per pair of axes, in its file's units
    scored = []
    for index, frame in enumerate(frame_candidates(units, up, front)):
        axes = (frame.up, frame.front)
        if axes not in crowns:
            crowns[axes] = crown(target.vertices @ frame.rotation.T)
        score = min(fit_score(head, head_crown, crowns[axes], query, frame, size) for size in HEAD_SCALES)
        scored.append((score, index, frame))
    scored.sort()
    best, _, frame = scored[0]
    return FrameFit(frame, best, scored[1][0] if len(scored) > 1 else float("inf"))
