"""Hair-root relocation for a hairline edit (paper Section 6.1, Section 7.5).

Convention: a target ``character`` (meters) whose roots, after the initial transfer, lie on
its faces ``root_faces (S,) int64`` at ``root_barycentric (S, 3) float64``. The edit is a
:class:`HairlineEdit`: a preset (:mod:`.presets`) or a drawn curve
(:class:`.curve.HairlineCurve`), the relocation method and the head parameterization.

Steps (:func:`relocate_roots`):

1. The scalp (:func:`.scalp.extract_scalp`): the faces holding roots made a disk, its
   hairline split at the ears, the front part's turning points.
2. A head patch around it (:func:`.head_patch.head_patch`) mapped to the unit disk
   (:func:`~hairport.solver.mesh.parameterization.parameterize`): the chart of Eq. 18-19
   (:class:`.head_chart.HeadChart`).
3. The scalp copy: its ears (triangles with two hairline edges, which a straighter
   hairline would flatten) split (:func:`.scalp.split_boundary_ears`), refined in
   the parameterization to at least ``min_triangles`` triangles
   (:func:`.scalp.refine_scalp`) and embedded on the head (Eq. 18-19).
4. The new front hairline. A drawn curve: its ends and turning points matched to the
   current ones, every front vertex mapped by normalised arc length between matched
   turning points (Section 6.1), then projected onto the head patch. A preset moves each
   front vertex to its own point (:mod:`.presets` builds one per vertex), which
   spares the hairline the arc-length re-parameterisation: on the mesh-edge staircase of
   a real hairline that squeezes and stretches the triangles along it (Table 3's L1 over 8
   grooms, straight edit: 0.053 with it, 0.043 without). The back part stays.
5. The scalp's interior follows: the embedded neo-Hookean membrane (Eq. 15,
   :func:`.newton.relocate`) or, for comparison (Section 7.5), a harmonic or thin-plate
   RBF displacement in the parameterization, or a 3D thin-plate RBF displacement reprojected
   onto the head (:mod:`.baselines`).
6. Each root keeps its barycentric coordinates in its refined scalp triangle. The paper
   interpolates in 3D and projects onto the head; interpolating the *parameters* and
   embedding them lands on the head directly (the same point up to the projection's
   discretisation error, which this way is zero). Roots outside the scalp (strays) stay.
7. Table 3's density change over the refined scalp triangles holding roots.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from hairport.solver.body.head_frame import HeadFrame, head_frame
from hairport.solver.hairline.baselines import (
    harmonic_displacement,
    interior_seeds,
    rbf_displacement_2d,
    rbf_displacement_3d,
)
from hairport.solver.hairline.curve import HairlineCurve, check_curve_on_head, smoothed_arc_length
from hairport.solver.hairline.density import DensityChange, density_change
from hairport.solver.hairline.edit import HairlineEdit, unknown_method
from hairport.solver.hairline.head_chart import HeadChart
from hairport.solver.hairline.head_patch import gap_hint, head_patch
from hairport.solver.hairline.membrane import Membrane
from hairport.solver.hairline.newton import relocate
from hairport.solver.hairline.presets import preset_curve
from hairport.solver.hairline.scalp import (
    DEFAULT_MIN_TRIANGLES,
    Scalp,
    extract_scalp,
    refine_scalp,
    split_boundary_ears,
)
from hairport.solver.mesh.parameterization import parameterize
from hairport.solver.mesh.polyline import polyline_arc_length
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.mesh.triangles import barycentric_coordinates, interpolate_barycentric
from hairport.solver.model.character import Character
from hairport.solver.model.errors import InputError

#: a drawn curve's ends must lie this close (m) to the ends of the current front hairline,
#: where it joins the fixed back part; they are then moved onto them
CURVE_END_TOLERANCE_M = 0.025
#: refusals of an edit that leaves the head patch (then a gap in the mesh nearby is named)
OFF_HEAD = ("hairline_off_head", "off_head")


@dataclass(frozen=True, eq=False)
class ScalpChart:
    """A target's scalp, refined, inside a parameterized patch of its head.

    Attributes
    ----------
    scalp : Scalp
        On the character's own faces.
    frame : HeadFrame
    rest : (n, 3) float64
        Refined scalp vertices (m), on the head.
    u_rest : (n, 2) float64
        Their parameters in ``chart``.
    triangles : (m, 3) int64
        Refined scalp triangles.
    boundary : (b,) int64
        The hairline loop (refined ids), starting with the front part.
    front : (f,) int64
        The front part (refined ids), right ear to left ear: ``boundary[:f]``.
    turning : (t,) int64
        Indices into ``front`` of its turning points (both ends included).
    chart : HeadChart
        The head patch with its parameterization.
    head : MeshQuery
        The head patch in 3D.
    patch_faces : (q,) int64
        Ascending character face ids of the patch, row for row with ``chart.faces``.
    parameterization : str
    """

    scalp: Scalp
    frame: HeadFrame
    rest: np.ndarray
    u_rest: np.ndarray
    triangles: np.ndarray
    boundary: np.ndarray
    front: np.ndarray
    turning: np.ndarray
    chart: HeadChart
    head: MeshQuery
    patch_faces: np.ndarray
    parameterization: str

    def parameters(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Chart parameters of the closest patch points to ``points (k, 3)``.

        Returns
        -------
        uv : (k, 2) float64
        distance : (k,) float64
            Unsigned distance (m) from each point to the patch.
        """
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        found = self.head.signed_distance(points)
        corners = self.chart.faces[found.faces]
        weights = barycentric_coordinates(found.closest, self.chart.vertices[corners])
        return interpolate_barycentric(self.chart.uv, self.chart.faces, found.faces, weights), np.abs(found.distance)

    def face_parameters(self, faces: np.ndarray, barycentric: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Chart parameters of points given on the character's faces.

        Parameters
        ----------
        faces : (k,) int64
            Character face ids.
        barycentric : (k, 3) float64

        Returns
        -------
        uv : (k, 2) float64
            NaN where the face is not in the patch.
        inside : (k,) bool
            The face is in the patch.
        """
        local = np.searchsorted(self.patch_faces, faces)
        local = np.minimum(local, len(self.patch_faces) - 1)
        inside = self.patch_faces[local] == faces
        uv = np.full((len(faces), 2), np.nan)
        uv[inside] = interpolate_barycentric(self.chart.uv, self.chart.faces, local[inside], barycentric[inside])
        return uv, inside


def scalp_chart(
    character: Character,
    root_faces: np.ndarray,
    parameterization: str = "harmonic",
    min_triangles: int = DEFAULT_MIN_TRIANGLES,
    frame: HeadFrame | None = None,
) -> ScalpChart:
    """Steps 1-3: scalp, parameterized head patch, refined scalp.

    Parameters
    ----------
    character : Character
        The target (its head frame from a ``head`` bone, or from the mesh without a rig).
    root_faces : (S,) int64
        Character face holding each root.
    parameterization : str
    min_triangles : int
    frame : HeadFrame, optional

    Raises
    ------
    InputError
        The roots do not make a scalp, or the head patch cannot be parameterized.
    """
    frame = frame or head_frame(character)
    scalp = extract_scalp(character, root_faces, frame)
    patch_vertices, patch_triangles, patch_faces = head_patch(character, scalp, frame=frame)
    patch_points = character.vertices[patch_vertices]
    uv = parameterize(patch_points, patch_triangles, parameterization)
    chart = HeadChart.build(patch_points, patch_triangles, uv)
    scalp_uv = uv[np.searchsorted(patch_vertices, scalp.vertices)]
    coarse_uv, coarse, _ = split_boundary_ears(scalp_uv, scalp.triangles)
    u_rest, triangles, boundary = refine_scalp(coarse_uv, coarse, scalp.boundary, min_triangles)
    rounds = int(round(np.log2(len(boundary) / len(scalp.boundary))))
    step = 2**rounds
    front = boundary[: step * (len(scalp.front) - 1) + 1]
    return ScalpChart(
        scalp, frame, chart.embed(u_rest), u_rest, triangles, boundary, front, step * scalp.turning_points, chart,
        MeshQuery(patch_points, patch_triangles), patch_faces, parameterization,
    )


def hairline_targets(setup: ScalpChart, curve: HairlineCurve, source: str = "hairline curve",
                     pointwise: bool = False) -> np.ndarray:
    """Step 4: where each front hairline vertex goes.

    The curve is oriented like the front hairline (right ear first), checked (on the head
    patch, not crossing itself on the head, i.e. in the chart, ends within
    :data:`CURVE_END_TOLERANCE_M` of the current ends, which it then takes), and its turning
    points are matched to the hairline's in order (both ends always match; interior ones must
    be as many as the hairline has, or none). Between matched turning points, the front
    vertex at normalised arc length ``t`` goes to the curve point at normalised arc length
    ``t``, projected onto the head patch. Arc lengths are measured on smoothed copies
    (:func:`.curve.smoothed_arc_length`): the hairline follows mesh edges in a staircase
    whose extra length would otherwise bunch the vertices up on a smooth curve. With
    ``pointwise`` the curve has one point per front vertex, which goes there (presets).

    Returns
    -------
    targets : (f, 3) float64
        On the head patch, row for row with ``setup.front``.

    Raises
    ------
    InputError
        ``off_head``, ``self_intersecting``, ``curve_ends_off`` or ``turning_points_mismatch``.
    """
    points = np.asarray(curve.points, dtype=np.float64).copy()
    turning = np.asarray(curve.turning_points, dtype=np.int64)
    frame = setup.frame
    front = setup.rest[setup.front]
    side = frame.local(points)[:, 2]
    if side[0] > side[-1]:  # drawn from the left ear: turn it around
        points = points[::-1].copy()
        turning = (len(points) - 1 - turning)[::-1]
    uv, distance = setup.parameters(points)
    check_curve_on_head(HairlineCurve(points, turning), distance, uv, source)
    ends = np.linalg.norm(points[[0, -1]] - front[[0, -1]], axis=1)
    if (ends > CURVE_END_TOLERANCE_M).any():
        raise InputError(
            f"the curve must start and end at the ends of the current front hairline (above the ears), "
            f"within {100 * CURVE_END_TOLERANCE_M:g} cm; its ends are {100 * ends[0]:.1f} cm and "
            f"{100 * ends[1]:.1f} cm away (right {np.round(front[0], 4).tolist()}, left "
            f"{np.round(front[-1], 4).tolist()})", source, "curve_ends_off")
    points[0], points[-1] = front[0], front[-1]
    if pointwise:
        if len(points) != len(front):
            raise InputError(f"a pointwise curve needs {len(front)} points, got {len(points)}", source, "bad_curve")
        return setup.head.signed_distance(points).closest
    hairline_turning = setup.turning
    inner = turning[(turning > 0) & (turning < len(points) - 1)]
    hairline_inner = hairline_turning[(hairline_turning > 0) & (hairline_turning < len(front) - 1)]
    if len(inner) and len(inner) != len(hairline_inner):
        raise InputError(
            f"the curve has {len(inner)} interior turning points but the hairline has {len(hairline_inner)} "
            f"(at {np.round(front[hairline_inner], 4).tolist()}); give as many, in order, or none",
            source, "turning_points_mismatch")
    curve_knots = np.concatenate([[0], inner, [len(points) - 1]]) if len(inner) else np.array([0, len(points) - 1])
    front_knots = (np.concatenate([[0], hairline_inner, [len(front) - 1]]) if len(inner)
                   else np.array([0, len(front) - 1]))
    front_arc, curve_arc = smoothed_arc_length(front), smoothed_arc_length(points)
    segment = np.clip(np.searchsorted(front_knots, np.arange(len(front)), side="right") - 1, 0, len(front_knots) - 2)
    a, b = front_arc[front_knots[segment]], front_arc[front_knots[segment + 1]]
    t = (front_arc - a) / (b - a)
    ca, cb = curve_arc[curve_knots[segment]], curve_arc[curve_knots[segment + 1]]
    raw_arc = polyline_arc_length(points)
    along = np.interp(ca + t * (cb - ca), curve_arc, raw_arc)
    on_curve = np.column_stack([np.interp(along, raw_arc, points[:, k]) for k in range(3)])
    return setup.head.signed_distance(on_curve).closest


def edit_curve(setup: ScalpChart, edit: HairlineEdit) -> HairlineCurve:
    """The edit's new front hairline (a preset applied to the current one, or the drawn curve)."""
    if edit.curve is not None:
        return edit.curve
    return preset_curve(edit.preset, edit.amount, setup.rest[setup.front], setup.turning, setup.frame, setup.head)


def deform_scalp(setup: ScalpChart, targets: np.ndarray, method: str = "membrane") -> tuple[np.ndarray, dict]:
    """Step 5: the scalp's new parameters with its front hairline at ``targets``.

    Parameters
    ----------
    setup : ScalpChart
    targets : (f, 3) float64
        New front hairline on the head patch.
    method : str
        One of :data:`.edit.RELOCATION_METHODS`.

    Returns
    -------
    u : (n, 2) float64
    report : dict
        Method-specific figures (membrane: Newton iterations, convergence, stages).

    Raises
    ------
    InputError
        The motion flips the membrane, or a baseline moves scalp vertices off the patch.
    """
    n = len(setup.rest)
    fixed = np.zeros(n, dtype=bool)
    fixed[setup.boundary] = True
    u_target = setup.u_rest.copy()
    u_target[setup.front], _ = setup.parameters(targets)
    u_fixed = u_target[fixed]
    report: dict = {}
    if method == "membrane":
        u, solve = relocate(Membrane.build(setup.rest, setup.triangles), setup.chart, setup.u_rest, fixed, u_fixed)
        report = {"iterations": solve.iterations, "converged": solve.converged, "stop": solve.stop,
                  "stages": solve.stages, "exact_steps": solve.exact_steps}
    elif method == "harmonic":
        u = harmonic_displacement(setup.u_rest, setup.triangles, fixed, u_fixed)
    else:
        seeds = interior_seeds(setup.triangles, setup.boundary, setup.rest)
        report = {"fixed_interior_vertices": int(len(seeds))}
        if method == "rbf2d":
            u = rbf_displacement_2d(setup.u_rest, fixed, u_fixed, seeds)
        elif method == "rbf3d":
            moved = rbf_displacement_3d(setup.rest, fixed, setup.chart.embed(u_fixed), seeds)
            u, _ = setup.parameters(moved)
            u[fixed] = u_fixed
        else:
            raise unknown_method(method)
    outside = int((setup.chart.locate(u)[0] < 0).sum())
    if outside:
        raise InputError(f"the {method} relocation moved {outside} scalp vertices off the head patch",
                         code="hairline_off_head")
    return u, report


@dataclass(eq=False)
class Relocation:
    """Relocated roots and what was measured.

    Attributes
    ----------
    roots : (S, 3) float64
        New root positions on the target (m).
    travel : (S,) float64
        How far each root moved (m).
    curve : HairlineCurve
        The requested front hairline (a preset's, or the drawn one).
    targets : (f, 3) float64
        Where the front hairline vertices went.
    u : (n, 2) float64
        Deformed scalp parameters.
    deformed : (n, 3) float64
        Deformed scalp vertices (m).
    density : DensityChange
    setup : ScalpChart
    report : dict
        JSON-ready figures (see :func:`relocate_roots`).
    """

    roots: np.ndarray
    travel: np.ndarray
    curve: HairlineCurve
    targets: np.ndarray
    u: np.ndarray
    deformed: np.ndarray
    density: DensityChange
    setup: ScalpChart
    report: dict


def relocate_roots(
    character: Character,
    root_faces: np.ndarray,
    root_barycentric: np.ndarray,
    edit: HairlineEdit,
    frame: HeadFrame | None = None,
) -> Relocation:
    """Move the roots for a hairline edit (steps 1-7 of the module docstring).

    Parameters
    ----------
    character : Character
        The target.
    root_faces : (S,) int64
    root_barycentric : (S, 3) float64
    edit : HairlineEdit
    frame : HeadFrame, optional

    Returns
    -------
    relocation : Relocation
        ``report`` holds ``density_change_l1``, ``density_change_linf``, ``seconds`` (the
        whole relocation), per-step seconds, the scalp and membrane sizes, roots moved and
        their mean and largest travel (m), and the method's own figures.
    """
    edit.validate()
    began = time.perf_counter()
    root_faces = np.asarray(root_faces, dtype=np.int64)
    root_barycentric = np.asarray(root_barycentric, dtype=np.float64)
    setup = scalp_chart(character, root_faces, edit.parameterization, edit.min_triangles, frame)
    prepared = time.perf_counter()
    try:
        curve = edit_curve(setup, edit)
        if edit.curve is not None:
            targets = hairline_targets(setup, curve)
        else:  # a preset moves each hairline vertex to its own point
            targets = hairline_targets(setup, curve, f"preset {edit.preset}", pointwise=True)
        u, method_report = deform_scalp(setup, targets, edit.method)
    except InputError as error:
        hint = gap_hint(character, setup.patch_faces, setup.rest[setup.front]) if error.code in OFF_HEAD else ""
        if not hint:
            raise
        raise InputError(error.problem + hint, error.source, error.code) from error
    deformed_at = time.perf_counter()

    roots_uv, in_patch = setup.face_parameters(root_faces, root_barycentric)
    locator = HeadChart.build(setup.rest, setup.triangles, setup.u_rest)
    host = np.full(len(root_faces), -1, dtype=np.int64)
    weights = np.zeros((len(root_faces), 3))
    host[in_patch], weights[in_patch] = locator.locate(roots_uv[in_patch])
    inside = host >= 0
    old = interpolate_barycentric(character.vertices, character.faces, root_faces, root_barycentric)
    roots = old.copy()
    new_uv = interpolate_barycentric(u, setup.triangles, host[inside], weights[inside])
    roots[inside] = setup.chart.embed(new_uv)
    travel = np.linalg.norm(roots - old, axis=1)
    deformed = setup.chart.embed(u)
    density = density_change(setup.rest, deformed, setup.triangles, host)
    finished = time.perf_counter()
    moved = travel > 0
    report = {
        "edit": edit.describe(),
        "method": edit.method,
        "parameterization": edit.parameterization,
        "head_frame": setup.frame.source,
        "density_change_l1": float(density.l1),
        "density_change_linf": float(density.linf),
        "seconds": finished - began,
        "scalp_seconds": prepared - began,
        "deform_seconds": deformed_at - prepared,
        "roots_seconds": finished - deformed_at,
        "scalp_faces": int(setup.scalp.n_faces),
        "scalp_closing_rings": int(setup.scalp.closing_rings),
        "membrane_triangles": int(len(setup.triangles)),
        "membrane_vertices": int(len(setup.rest)),
        "hairline_vertices": int(len(setup.boundary)),
        "front_vertices": int(len(setup.front)),
        "turning_points": int(len(setup.turning)),
        "roots": int(len(root_faces)),
        "roots_moved": int(moved.sum()),
        "roots_outside_scalp": int((~inside).sum()),
        "mean_travel_m": float(travel[moved].mean()) if moved.any() else 0.0,
        "max_travel_m": float(travel.max()) if len(travel) else 0.0,
        **method_report,
    }
    return Relocation(roots, travel, curve, targets, u, deformed, density, setup, report)
