"""The compiled kernels: ``hairport warmup`` compiles every signature a retarget uses, and a
second process loads them from numba's on-disk cache instead of compiling."""

import importlib
import json
import re
import subprocess
import sys

from hairport.solver import jit

#: ``hairport warmup``'s summary line
SUMMARY = re.compile(r"(\d+) kernels: (\d+) signatures compiled, (\d+) loaded from the cache")

#: a warmed process that then preprocesses and retargets a small groom (multi-scale, both
#: levels, then the global solve) and prints the kernel signatures the solve added: each one
#: would be a compilation in a worker that had warmed up
NEW_SIGNATURES_AFTER_WARMUP = """
import importlib
import json
from hairport import solver
from hairport.solver import jit
from hairport.solver.synthetic.groom import generate_groom
from hairport.solver.synthetic.toy import toy_character
solver.warm_up()
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


def test_a_second_process_loads_every_kernel_from_the_cache():
    kernels, _, _ = _warmup()  # compiles what the cache lacks
    again, compiled, loaded = _warmup()
    assert again == kernels >= 10
    assert compiled == 0 and loaded >= 10  # (kernels called only by other kernels have no signature of their own)


def test_the_warm_up_covers_every_signature_a_retarget_calls():
    assert json.loads(_run("-c", NEW_SIGNATURES_AFTER_WARMUP).strip().splitlines()[-1]) == []


def test_warm_up_reports_each_kernel_module():
    done = jit.warm_up()
    assert set(done.seconds) and all(seconds >= 0 for seconds in done.seconds.values())
    assert done.kernels == len(jit._KERNELS) >= 10


#: a module declaring one kernel, written to a temporary folder (numba caches beside it)
FRESH_KERNEL_MODULE = '''
from hairport.solver.jit import kernel


@kernel
def twice(x):
    return 2.0 * x
'''


def test_a_kernel_counts_as_uncached_until_its_first_call_stores_it(tmp_path, monkeypatch):
    jit.warm_up()
    uncached, declared = jit.uncached_kernels()
    # after the warm-up only kernels that no warmer calls directly (called by other kernels) lack a cache entry
    assert uncached <= declared // 10
    (tmp_path / "fresh_kernel_module.py").write_text(FRESH_KERNEL_MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    module = importlib.import_module("fresh_kernel_module")
    try:
        assert jit.uncached_kernels() == (uncached + 1, declared + 1)
        assert module.twice(2.0) == 4.0  # compiled, and written to numba's cache
        assert jit.uncached_kernels() == (uncached, declared + 1)
    finally:
        jit._KERNELS.remove(module.twice)
        sys.modules.pop("fresh_kernel_module", None)
