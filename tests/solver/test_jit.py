"""The kernel declarations: a kernel counts as uncached until its first call stores its machine code in
numba's on-disk cache, and a module's warmer is registered under the module's name."""

import importlib
import sys

from hairport.solver import jit, kernels

#: a module declaring one kernel and its warmer, written to a temporary folder (numba caches beside it)
FRESH_KERNEL_MODULE = '''
from hairport.solver.jit import kernel, warms


@kernel
def twice(x):
    return 2.0 * x


@warms
def _warm():
    twice(1.0)
'''


def test_a_kernel_counts_as_uncached_until_its_first_call_stores_it(tmp_path, monkeypatch):
    kernels.warm_up()
    uncached, declared = jit.count_uncached()
    (tmp_path / "fresh_kernel_module.py").write_text(FRESH_KERNEL_MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    module = importlib.import_module("fresh_kernel_module")
    try:
        assert jit.count_uncached() == (uncached + 1, declared + 1)
        # the warmer is registered under its module's name, and run with the others
        assert "fresh_kernel_module" in jit.run_warmers().seconds
        assert module.twice(2.0) == 4.0
        assert jit.count_uncached() == (uncached, declared + 1)
    finally:
        jit._KERNELS.remove(module.twice)
        jit._WARMERS.pop("fresh_kernel_module", None)
        sys.modules.pop("fresh_kernel_module", None)
