"""The mesh kernels are registered for the warm-up (solver/kernels.py) and their warmers run."""

import numpy as np

from hairport.solver import kernels
from hairport.solver.mesh import closest_kernels


def test_the_mesh_kernel_modules_are_registered_and_warm_up():
    mesh_modules = {"hairport.solver.mesh.bvh_build", "hairport.solver.mesh.closest_kernels", "hairport.solver.mesh.distance_grid"}
    assert mesh_modules <= {module.__name__ for module in kernels.MODULES}
    seconds = kernels.warm_up().seconds
    assert mesh_modules <= set(seconds) and all(value >= 0 for value in seconds.values())


def test_the_cell_table_finds_what_was_inserted_and_nothing_else():
    rng = np.random.default_rng(3)
    keys = rng.choice(10**9, size=300, replace=False).astype(np.int64)
    values = rng.integers(0, 10**6, size=300).astype(np.int64)
    slots = np.full((1024, 2), closest_kernels.EMPTY, dtype=np.int64)
    closest_kernels.insert_cells(keys[:200], values[:200], slots)
    found = closest_kernels.lookup_all(keys, slots)
    np.testing.assert_array_equal(found[:200], values[:200])
    assert np.all(found[200:] == closest_kernels.EMPTY)


def test_cell_keys_round_trip_through_the_z_order():
    # cells of a 4 x 4 x 4 block: distinct keys, and the Z-curve visits the 8 cells of each 2 x 2 x 2 octant together
    origin, size = np.zeros(3), 1.0
    centres = np.stack(np.meshgrid(*[np.arange(4) + 0.5] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    keys = closest_kernels.cell_keys(centres, origin, 1.0 / size)
    assert len(np.unique(keys)) == 64
    visited = centres[np.argsort(closest_kernels.z_order(keys))]
    octants = (visited // 2).reshape(8, 8, 3)
    assert all(len(np.unique(octant, axis=0)) == 1 for octant in octants)
