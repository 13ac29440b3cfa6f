"""The options of the two stages, with their defaults and ranges (Table 1, meters): the one place they are defined.

A public module of the solver (``from hairport.solver import options``): besides the two option sets, it
names every choice an option takes (methods, anchorings, QP back-ends, hairline presets, relocation
methods, parameterizations, the guide flag's attribute name), which the command line and the API's
schemas list.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hairport.solver.adaptation.multiscale import DEFAULT_CHUNK_PARTICLES
from hairport.solver.adaptation.problem.energies import EnergyWeights
from hairport.solver.adaptation.problem.spacing import EVEN_SPACING_WEIGHT as EVEN_SPACING_WEIGHT
from hairport.solver.adaptation.problem.spacing import SPACING_BAND, SPACING_WEIGHT
from hairport.solver.adaptation.solve import QP_BACKENDS as QP_BACKENDS
from hairport.solver.adaptation.source.guide_flags import GUIDE_FLAG as GUIDE_FLAG
from hairport.solver.adaptation.source.guides import DEFAULT_GUIDES
from hairport.solver.baselines import BASELINE_METHODS, parse_method
from hairport.solver.hairline.edit import RELOCATION_METHODS as RELOCATION_METHODS
from hairport.solver.hairline.edit import HairlineEdit
from hairport.solver.hairline.presets import PRESETS
from hairport.solver.mesh.parameterization import PARAMETERIZATIONS as PARAMETERIZATIONS
from hairport.solver.model.errors import InputError
from hairport.solver.model.landmarks import BAD_LANDMARKS, LandmarkPairs
from hairport.solver.model.landmarks import MAX_LANDMARK_NAME_CHARS as MAX_LANDMARK_NAME_CHARS
from hairport.solver.model.landmarks import MAX_LANDMARKS as MAX_LANDMARKS
from hairport.solver.transfer.anchors import ANCHOR_AUTO, ANCHOR_SIGMA, ANCHORINGS
from hairport.solver.transfer.anchors import ANCHOR_BY_BONES as ANCHOR_BY_BONES
from hairport.solver.transfer.carry import CARRY_LENGTH_M
from hairport.solver.transfer.smoothing import SMOOTHING_EPS

#: the shape-adaptation solvers: guides then independent strands (Sec. 5), or all strands coupled
SOLVER_METHODS = ("multiscale", "global")
METHODS = SOLVER_METHODS + BASELINE_METHODS
#: the named edits of the front hairline (``hairline.preset``)
HAIRLINE_PRESETS = PRESETS
#: when a retarget wraps the source body onto the target (:mod:`hairport.solver.wrapping`): ``auto`` when the
#: target's topology is not the source's; ``always``, a same-topology target too; ``off`` never (another
#: topology is then ``topology_mismatch``)
WRAP_MODES = ("auto", "always", "off")


#: the solvers stop a strand (or the coupled guides) once an iteration lowers Eq. 1 by less
#: than this fraction (see SolveOptions.energy_tolerance)
ENERGY_TOLERANCE = 1e-3


@dataclass(frozen=True)
class OptionRange:
    """The accepted values of one numeric option: ``minimum <= value <= maximum``, finite."""

    minimum: float
    maximum: float
    integer: bool
    units: str
    description: str

    def check(self, name: str, value) -> None:
        """Refuse (``bad_option``) a value outside the range, NaN, infinite, or not a number."""
        if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
            raise InputError(f"option {name} must be a number, got {value!r}", code="bad_option")
        if self.integer and not float(value).is_integer():
            raise InputError(f"option {name} must be an integer, got {value!r}", code="bad_option")
        if not (np.isfinite(value) and self.minimum <= value <= self.maximum):
            raise InputError(f"option {name} must be {self.text()}, got {value!r}", code="bad_option")

    def text(self) -> str:
        """``"in [1, 64] (neighbours)"``: the range in words, for messages."""
        return f"in [{self.minimum:g}, {self.maximum:g}]" + (f" ({self.units})" if self.units else "")


#: every numeric option of both stages: the one definition of its range, from which the API
#: schema (Field ge/le), the command line (argparse types) and ``validate()`` are derived and
#: docs/operations.md's table is generated (:func:`option_table`). The upper bounds keep one job
#: within a worker's means: k and guides size the kNN sets and the coupled QP, eps_c beyond a
#: few cm leaves the distance grid's narrow band, iterations bound the time.
OPTION_RANGES: dict[str, OptionRange] = {
    "k": OptionRange(1, 64, True, "neighbours", "inter-strand neighbours per particle (Eq. 8)"),
    "sigma": OptionRange(0, 1e6, False, "", "Eq. 2's penalty on rays along their bone"),
    "guides": OptionRange(1, 20_000, True, "strands", "guide strands of the multi-scale solve"),
    "guide_seed": OptionRange(0, 2**32 - 1, True, "", "seed of the guide selection"),
    "alpha": OptionRange(0, 1e9, False, "", "inter-strand weight (Eq. 1)"),
    "beta": OptionRange(0, 1e9, False, "", "hair-body weight (Eq. 1)"),
    "spacing": OptionRange(0, 1e6, False, "", "weight keeping particles evenly spaced along their strand "
                           "(beyond the paper; 0: Eq. 1 exactly)"),
    "eps_c": OptionRange(0, 0.02, False, "m", "clearance to the body (Eq. 13)"),
    "carry": OptionRange(0, 1, False, "m", "length over which the anchored strands take back their source shape "
                         "(beyond the paper; 0: Eq. 2-6 alone)"),
    "eps_s": OptionRange(0, 100, False, "", "Laplacian discrepancy that marks a strand for smoothing (Eq. 6)"),
    "max_iterations": OptionRange(1, 1000, True, "iterations", "cap on outer solver iterations"),
    "step_tolerance": OptionRange(0, 0.01, False, "m", "converged when no particle moves more than this"),
    "energy_tolerance": OptionRange(0, 1, False, "", "stop a strand whose Eq. 1 fell by less than this fraction"),
    "workers": OptionRange(1, 256, True, "processes", "processes of the multi-scale fine level"),
    "chunk_particles": OptionRange(1, 10**8, True, "particles", "particles per fine-level chunk"),
    "temporal": OptionRange(0, 1e9, False, "", "weight, as beta's, of a pull toward the previous frame's result "
                            "moved with the body (sequences; 0: each frame's own Eq. 1)"),
}


def check_ranges(options) -> None:
    """Check every option of ``options`` (a dataclass) that has a range; ``None`` means default."""
    for name, spec in OPTION_RANGES.items():
        value = getattr(options, name, None)
        if value is not None:
            spec.check(name, value)


def option_table(names=None) -> str:
    """docs/operations.md's table of option ranges (Markdown), generated from :data:`OPTION_RANGES`."""
    rows = ["| option | min | max | units | what |", "|---|---|---|---|---|"]
    for name, spec in OPTION_RANGES.items():
        if names is None or name in names:
            rows.append(f"| `{name}` | {spec.minimum:g} | {spec.maximum:g} | {spec.units or '-'} | {spec.description} |")
    return "\n".join(rows)


#: the spacing term's weight of a sequence's frames unless the retarget's options name one: it keeps segments from
#: stretching near the body in one frame and springing back in the next (single particles jumping 21-25 mm against a
#: 17-20 mm bound at 10^6 particles without it), and it holds warm frames within 0.2 mm of cold retargets
#: (0.5-0.8 mm without it); measured by ``bench/sequence.py --spacing`` (docs/performance.md, "Sequences")
SEQUENCE_SPACING = 3.0


@dataclass(frozen=True)
class SequenceOptions:
    """How the frames of a target sequence are solved (:mod:`~hairport.solver.sequence`).

    ``warm``: each frame starts from the previous frame's result, moved as the body moved (the
    difference of the two frames' initial transfers), instead of from its own initial transfer.
    ``temporal``: a weight, as ``beta``'s, of a pull of each particle toward that moved result, joined to
    Eq. 11 (needs ``warm``); 0 leaves Eq. 1 as it is.
    """

    warm: bool = True
    temporal: float = 0.0

    def validate(self) -> None:
        check_ranges(self)
        if self.temporal and not self.warm:
            raise InputError("option temporal anchors a frame to the previous one, which needs warm starts",
                             code="bad_option")


@dataclass(frozen=True)
class PreprocessOptions:
    """Source-side parameters (Table 1, meters).

    ``anchoring`` (:data:`~hairport.solver.transfer.anchors.ANCHORINGS`) anchors particles
    by the bones (Eq. 2), by the body surface, or ``auto``: by the bones when the source has a
    skeleton with skin weights, else by the surface. An adaptable hairstyle records the one used.
    ``guides_from`` names a per-strand attribute whose non-zero strands are the guides (e.g.
    Unreal's ``groom_guide``) instead of the k-means selection of ``guides`` strands.
    """

    k: int = 5
    sigma: float = ANCHOR_SIGMA
    guides: int = DEFAULT_GUIDES
    guide_seed: int = 0
    anchoring: str = ANCHOR_AUTO
    guides_from: str | None = None

    def validate(self) -> None:
        if self.anchoring not in ANCHORINGS:
            raise InputError(f"unknown anchoring {self.anchoring!r}; expected one of {', '.join(ANCHORINGS)}",
                             code="bad_option")
        check_ranges(self)


@dataclass(frozen=True)
class RetargetOptions:
    """Target-side parameters (Table 1, meters) and the method.

    ``method`` is ``multiscale`` (Sec. 5), ``global`` (Eq. 1 over all strands coupled) or a
    baseline name, optionally with the ``+pushout`` suffix. The multi-scale fine level runs in
    chunks of ``chunk_particles``, in this process on numba's threads (``workers`` ``None`` or
    1), or in ``workers`` processes.
    ``qp_backend`` solves the coupled QPs (``global``, and the guides of ``multiscale``): the
    active-set method of :mod:`~hairport.solver.adaptation.loop.active_set` or OSQP. ``hairline`` edits the front
    hairline (Sec. 6; solver methods only). ``spacing`` weighs the term beyond the paper that keeps
    particles evenly spaced along their strands (:mod:`~hairport.solver.adaptation.problem.spacing`); 0 solves
    the paper's Eq. 1 exactly. ``carry`` (m) lets the anchored strands take back their source shape
    before the solve (:mod:`~hairport.solver.transfer.carry`); 0 is the paper's initial transfer.
    ``wrap`` (:data:`WRAP_MODES`) says when the source body is wrapped onto the target first; ``landmarks``
    (canonical frame, :meth:`~hairport.solver.model.landmarks.LandmarkPairs.in_canonical`) help that wrap.
    """

    method: str = "multiscale"
    alpha: float = 3e3
    beta: float = 1e3
    spacing: float = SPACING_WEIGHT
    carry: float = CARRY_LENGTH_M
    eps_c: float = 5e-4
    eps_s: float = SMOOTHING_EPS
    max_iterations: int = 30
    step_tolerance: float = 1e-5
    energy_tolerance: float = ENERGY_TOLERANCE
    workers: int | None = None
    chunk_particles: int = DEFAULT_CHUNK_PARTICLES
    qp_backend: str = "active-set"
    hairline: HairlineEdit | None = None
    wrap: str = WRAP_MODES[0]
    landmarks: LandmarkPairs | None = None

    def validate(self) -> None:
        if self.wrap not in WRAP_MODES:
            raise InputError(f"unknown wrap mode {self.wrap!r}; expected one of {', '.join(WRAP_MODES)}",
                             code="bad_option")
        if self.landmarks is not None and self.wrap == WRAP_MODES[2]:
            raise InputError(f"landmarks steer the wrap, and the wrap mode {self.wrap} never wraps", "landmarks",
                             BAD_LANDMARKS)
        if self.method not in SOLVER_METHODS:
            try:
                parse_method(self.method)
            except InputError:
                raise InputError(
                    f"unknown method {self.method!r}; expected one of {', '.join(METHODS)} "
                    "(a baseline may carry the suffix +pushout)",
                    code="unknown_method",
                ) from None
        check_ranges(self)
        if self.qp_backend not in QP_BACKENDS:
            raise InputError(
                f"unknown QP backend {self.qp_backend!r}; expected one of {', '.join(QP_BACKENDS)}", code="bad_option"
            )
        if self.hairline is not None:
            if self.method not in SOLVER_METHODS:
                raise InputError(
                    f"a hairline edit needs the method multiscale or global, not the baseline {self.method!r}",
                    code="bad_option",
                )
            self.hairline.validate()

    def energy_weights(self) -> EnergyWeights:
        """The weights of the energy the shape adaptation minimises."""
        return EnergyWeights(self.alpha, self.beta, self.spacing, SPACING_BAND)
