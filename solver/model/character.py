"""Characters: a triangle mesh with a skeleton and skin weights.

Convention: ``vertices (V, 3) float64`` in meters, ``faces (F, 3) int64`` counter-clockwise
seen from outside. A skeleton is a list of bones, each a segment from ``head`` to ``tail``
with a parent (``-1`` for a root bone); skin weights are a sparse ``(V, B)`` matrix whose
column ``b`` belongs to bone ``b``, each row with a positive sum summing to 1
(:func:`normalise_weight_rows`). Source and target characters share one topology: the
same vertex count and the same faces, vertex for vertex.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from hairport.solver.model.errors import InputError, TopologyMismatch


@dataclass(frozen=True, eq=False)
class Skeleton:
    """Bones as segments.

    Attributes
    ----------
    names : tuple of str, length B
    parents : (B,) int64
        Index of each bone's parent, ``-1`` for none.
    heads : (B, 3) float64
    tails : (B, 3) float64
    """

    names: tuple[str, ...]
    parents: np.ndarray
    heads: np.ndarray
    tails: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "names", tuple(self.names))
        object.__setattr__(self, "parents", np.asarray(self.parents, dtype=np.int64))
        object.__setattr__(self, "heads", np.asarray(self.heads, dtype=np.float64).reshape(-1, 3))
        object.__setattr__(self, "tails", np.asarray(self.tails, dtype=np.float64).reshape(-1, 3))
        n = len(self.names)
        if len(set(self.names)) != n:
            raise InputError("skeleton has duplicate bone names", code="bad_skeleton")
        if self.parents.shape != (n,) or self.heads.shape != (n, 3) or self.tails.shape != (n, 3):
            raise InputError("skeleton arrays disagree in bone count", code="bad_skeleton")
        if not (np.isfinite(self.heads).all() and np.isfinite(self.tails).all()):
            raise InputError("skeleton has a non-finite joint position", code="non_finite")
        if n and (self.parents.min() < -1 or self.parents.max() >= n):
            raise InputError("skeleton parent index out of range", code="bad_skeleton")

    @property
    def n_bones(self) -> int:
        return len(self.names)

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"no bone named {name!r}") from None

    def scaled(self, factor: float) -> "Skeleton":
        return Skeleton(self.names, self.parents, self.heads * factor, self.tails * factor)


@dataclass(frozen=True, eq=False)
class Character:
    """A body mesh, optionally rigged.

    Attributes
    ----------
    vertices : (V, 3) float64
        Meters.
    faces : (F, 3) int64
    skeleton : Skeleton or None
    weights : (V, B) scipy.sparse.csr_matrix or None
        Skin weights, column ``b`` for ``skeleton.names[b]``.
    name : str
        Where it came from, for messages.
    """

    vertices: np.ndarray
    faces: np.ndarray
    skeleton: Skeleton | None = None
    weights: sp.csr_matrix | None = field(default=None)
    name: str = "character"

    def __post_init__(self) -> None:
        vertices = np.ascontiguousarray(self.vertices, dtype=np.float64)
        faces = np.ascontiguousarray(self.faces, dtype=np.int64)
        object.__setattr__(self, "vertices", vertices)
        object.__setattr__(self, "faces", faces)
        if vertices.ndim != 2 or vertices.shape[1] != 3 or len(vertices) < 3:
            raise InputError(f"mesh vertices have shape {vertices.shape}, expected (V>=3, 3)", self.name, "bad_mesh")
        if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) < 1:
            raise InputError(f"mesh faces have shape {faces.shape}, expected triangles (F, 3)", self.name, "bad_mesh")
        if not np.isfinite(vertices).all():
            raise InputError("mesh has a non-finite vertex coordinate", self.name, "non_finite")
        if faces.min() < 0 or faces.max() >= len(vertices):
            raise InputError("mesh face index out of range", self.name, "bad_mesh")
        if self.weights is not None:
            weights = sp.csr_matrix(self.weights, dtype=np.float64)
            if self.skeleton is None:
                raise InputError("skin weights given without a skeleton", self.name, "bad_skeleton")
            if weights.shape != (len(vertices), self.skeleton.n_bones):
                raise InputError(
                    f"skin weights have shape {weights.shape}, expected "
                    f"({len(vertices)}, {self.skeleton.n_bones})",
                    self.name,
                    "bad_skeleton",
                )
            object.__setattr__(self, "weights", weights)

    @property
    def n_vertices(self) -> int:
        return len(self.vertices)

    @property
    def n_faces(self) -> int:
        return len(self.faces)

    def with_vertices(self, vertices: np.ndarray, skeleton: Skeleton | None = None, name: str | None = None) -> "Character":
        """Same topology and weights, new positions (and optionally a new skeleton)."""
        return Character(vertices, self.faces, skeleton if skeleton is not None else self.skeleton,
                         self.weights, name or self.name)


def check_same_topology(source: Character, target: Character) -> None:
    """Raise :class:`TopologyMismatch` unless both meshes have the same vertex count and faces."""
    if source.n_vertices != target.n_vertices:
        raise TopologyMismatch(
            # no file names in the problem (in the service they are storage names); the source says which
            f"topology differs: the source has {source.n_vertices} vertices, the target has {target.n_vertices}",
            target.name,
        )
    if source.faces.shape != target.faces.shape or not np.array_equal(source.faces, target.faces):
        if source.faces.shape != target.faces.shape:
            detail = f"source has {source.n_faces} faces, target has {target.n_faces}"
        else:
            first = int(np.argmax((source.faces != target.faces).any(axis=1)))
            detail = f"face {first} differs ({source.faces[first].tolist()} vs {target.faces[first].tolist()})"
        raise TopologyMismatch(f"topology differs: {detail}", target.name)


def normalise_weight_rows(weights: sp.spmatrix) -> sp.csr_matrix:
    """Divide every row with a positive sum by its sum; all-zero rows stay zero.

    Parameters
    ----------
    weights : (V, B) sparse matrix
        Non-negative; duplicate entries are summed first.

    Returns
    -------
    weights : (V, B) scipy.sparse.csr_matrix of float64
        Without stored zeros.
    """
    weights = sp.csr_matrix(weights, dtype=np.float64)
    weights.sum_duplicates()
    weights.eliminate_zeros()
    sums = np.asarray(weights.sum(axis=1)).ravel()
    scale = np.where(sums > 0, 1.0 / np.where(sums > 0, sums, 1.0), 0.0)
    return sp.csr_matrix(sp.diags(scale) @ weights)
