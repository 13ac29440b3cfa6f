"""The adaptable hairstyle: everything retargeting needs that depends on the source only (paper Sec. 5)."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from hairport.solver.adaptation.multiscale import FineSource, MultiscaleModel, coarse_shape_model, fine_source
from hairport.solver.adaptation.problem.energies import ShapeModel
from hairport.solver.adaptation.source.neighbours import Neighbours, knn_shaped_strands, laplacian_operator
from hairport.solver.model.character import Character
from hairport.solver.model.frame import InputFrame
from hairport.solver.model.hair import Hair
from hairport.solver.options import PreprocessOptions
from hairport.solver.transfer.anchors import Anchors
from hairport.solver.transfer.smoothing import strand_laplacian


@dataclass(frozen=True, eq=False)
class AdaptableHairstyle:
    """Everything retargeting needs that depends on the source only."""

    source: Character
    hair: Hair
    anchors: Anchors
    multiscale: MultiscaleModel
    options: PreprocessOptions
    bone_names: tuple[str, ...]
    timings: dict = field(default_factory=dict)
    #: the groom file's frame (units, axes): results are written back in it
    frame: InputFrame = field(default_factory=InputFrame)
    #: the report's ``input`` section, measured when the inputs were brought into hairport's frame
    input_report: dict = field(default_factory=dict)

    # derived from the source only: built once, reused by every retarget of this hairstyle
    # (cached_property writes the instance __dict__ directly, which a frozen dataclass allows)
    @cached_property
    def neighbours(self) -> Neighbours:
        """Eq. 8-9 over all strands: the metrics' inter-strand figures, and the coupled ``global`` solve's ``K``
        (``(N, k)`` int32 indices and float64 weights, built on the first retarget); collapsed strands have
        none and are none (:func:`~.adaptation.source.neighbours.knn_shaped_strands`)."""
        return knn_shaped_strands(self.hair, self.options.k)

    @cached_property
    def coarse_model(self) -> ShapeModel:
        """Eq. 7/10 operators of the guide hairstyle."""
        return coarse_shape_model(self.hair, self.multiscale)

    @cached_property
    def fine_source(self) -> FineSource:
        """Source-only arrays of the fine level."""
        return fine_source(self.hair, self.multiscale)

    @cached_property
    def shape_model(self) -> ShapeModel:
        """Eq. 7/10 operators of the whole hairstyle (the coupled ``global`` solve only)."""
        n = self.hair.n_particles
        K = laplacian_operator(self.neighbours, np.arange(n), n)
        return ShapeModel.build(self.hair.points, self.hair.segments, K)

    @cached_property
    def strand_laplacian(self):
        """Eq. 5's per-strand Laplacian of the source, ``(N, N)`` csr_matrix."""
        return strand_laplacian(self.hair.points, self.hair.offsets)
