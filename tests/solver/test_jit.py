"""The compiled kernels: ``hairport warmup`` compiles every signature a retarget uses, and a
second process loads them from numba's on-disk cache instead of compiling."""

import json
import os
import re
import subprocess
import sys
from pathlib import Path

from hairport.solver import jit

#: ``hairport warmup``'s summary line
SUMMARY = re.compile(r"(\d+) kernels: (\d+) signatures compiled, (\d+) loaded from the cache")

#: a warmed process that then preprocesses and retargets a small groom (multi-scale, both
#: levels, then the global solve) and prints what the kernels compiled and loaded
RETARGET_AFTER_WARMUP = """
import json
from hairport import solver
from hairport.solver import jit
from hairport.solver.synthetic.groom import generate_groom
from hairport.solver.synthetic.toy import toy_character
solver.warm_up()
source, target = toy_character(), toy_character(head_scale=(1.15, 1.1, 1.2), shoulder_width=0.44)
hair = generate_groom(source, "long", 60, 12, seed=0)
adaptable = solver.preprocess(source, hair, solver.PreprocessOptions(guides=12))
for method in ("multiscale", "global"):
    solver.retarget(adaptable, target, solver.RetargetOptions(method=method))
compiled, loaded = jit._cache_counts()
print(json.dumps({"compiled": compiled, "loaded": loaded, "kernels": len(jit._KERNELS)}))
"""


def _run(cache: Path, *arguments: str) -> str:
    environment = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    return subprocess.run([sys.executable, *arguments], capture_output=True, text=True, timeout=900, check=True,
                          env=environment).stdout


def test_a_warmed_process_compiles_nothing_during_a_retarget(tmp_path):
    # an empty cache of its own: what the retarget finds there, only the warm-up can have put
    first = SUMMARY.search(_run(tmp_path, "-m", "hairport.cli", "warmup")).groups()
    kernels, compiled_first, _ = (int(group) for group in first)
    assert compiled_first >= kernels >= 10
    again, compiled, loaded = (int(group) for group in SUMMARY.search(_run(tmp_path, "-m", "hairport.cli", "warmup")).groups())
    assert again == kernels
    assert compiled == 0 and loaded >= 10  # the second process found everything in the cache
    counts = json.loads(_run(tmp_path, "-c", RETARGET_AFTER_WARMUP).strip().splitlines()[-1])
    # every signature the solve called was warmed (and so came from the cache)
    assert counts["compiled"] == 0 and counts["loaded"] >= loaded, counts


def test_warm_up_reports_each_kernel_module():
    done = jit.warm_up()
    assert set(done.seconds) and all(seconds >= 0 for seconds in done.seconds.values())
    assert done.kernels == len(jit._KERNELS) >= 10
