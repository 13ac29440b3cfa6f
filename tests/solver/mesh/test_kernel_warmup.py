"""The mesh kernels are registered for the warm-up (solver/jit.py) and their warmers run."""

from hairport.solver import jit


def test_the_mesh_kernel_modules_are_registered_and_warm_up():
    mesh_modules = {"hairport.solver.mesh.closest_kernels", "hairport.solver.mesh.distance_grid"}
    assert mesh_modules <= set(jit.KERNEL_MODULES)
    seconds = jit.warm_up().seconds
    assert mesh_modules <= set(seconds) and all(value >= 0 for value in seconds.values())
