"""Every compiled kernel is registered from above: ``hairport warmup`` compiles every signature a retarget
uses, and a second process loads them from numba's on-disk cache instead of compiling."""

import json
import re
import subprocess
import sys

import hairport.solver  # noqa: F401 - the whole solver, so that every module declaring a kernel is imported
from hairport.solver import jit, kernels

#: ``hairport warmup``'s summary line
SUMMARY = re.compile(r"(\d+) kernels: (\d+) signatures compiled, (\d+) loaded from the cache")

#: a warmed process that then preprocesses and retargets a small groom (multi-scale, both
#: levels, then the global solve) and prints the kernel signatures the solve added: each one
#: would be a compilation in a worker that had warmed up
NEW_SIGNATURES_AFTER_WARMUP = """
import json
from hairport import solver
from hairport.solver import jit, kernels
from hairport.solver.synthetic.groom import generate_groom
from hairport.solver.synthetic.toy import toy_character
kernels.warm_up()
warmed = {id(kernel): set(kernel.signatures) for kernel in jit._KERNELS}
source, target = toy_character(), toy_character(head_scale=(1.15, 1.1, 1.2), shoulder_width=0.44)
hair = generate_groom(source, "long", 60, 12, seed=0)
adaptable = solver.preprocess(source, hair, solver.PreprocessOptions(guides=12))
for method in ("multiscale", "global"):
    solver.retarget(adaptable, target, solver.RetargetOptions(method=method))
print(json.dumps(sorted(f"{kernel.py_func.__module__}.{kernel.py_func.__qualname__}{signature}"
                        for kernel in jit._KERNELS for signature in set(kernel.signatures) - warmed[id(kernel)])))
"""


def _run(*arguments: str) -> str:
    return subprocess.run([sys.executable, *arguments], capture_output=True, text=True, timeout=900,
                          check=True).stdout


def _warmup() -> tuple[int, int, int]:
    return tuple(int(group) for group in SUMMARY.search(_run("-m", "hairport.cli", "warmup")).groups())


def test_every_module_that_declares_a_kernel_is_listed_and_warmed():
    declaring = {dispatcher.py_func.__module__ for dispatcher in jit._KERNELS}
    listed = {module.__name__ for module in kernels.MODULES}
    assert declaring == listed
    warmed = set(kernels.warm_up().seconds)
    # every listed module has a warmer, except those whose kernels only other kernels call
    assert warmed <= listed and len(listed - warmed) <= 1, listed - warmed


def test_a_second_process_loads_every_kernel_from_the_cache():
    declared, _, _ = _warmup()  # compiles what the cache lacks
    again, compiled, loaded = _warmup()
    assert again == declared >= 10
    assert compiled == 0 and loaded >= 10  # (kernels called only by other kernels have no signature of their own)


def test_the_warm_up_covers_every_signature_a_retarget_calls():
    assert json.loads(_run("-c", NEW_SIGNATURES_AFTER_WARMUP).strip().splitlines()[-1]) == []


def test_warm_up_reports_each_kernel_module():
    done = kernels.warm_up()
    assert set(done.seconds) and all(seconds >= 0 for seconds in done.seconds.values())
    assert done.kernels == len(jit._KERNELS) >= 10
    uncached, declared = kernels.uncached_kernels()
    # after the warm-up only kernels that no warmer calls directly (called by other kernels) lack a cache entry
    assert declared == done.kernels and uncached <= declared // 10
