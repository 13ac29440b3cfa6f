"""The memory budget of a worker child: past it an allocation raises MemoryError; BLAS threads still work."""

import subprocess
import sys

CHILD = """
import numpy as np, scipy.sparse as sp, scipy.sparse.linalg as sla, threading
from hairport.worker.memory import data_bytes, limit_memory
budget = data_bytes() + 300 * 1024**2
assert limit_memory(budget) == budget
a = np.ones((2000, 2000))
assert float((a @ a)[0, 0]) == 2000.0   # BLAS threads under the limit
m = sp.eye(10000, format="csc") * 2.0
assert abs(sla.spsolve(m, np.ones(10000))[0] - 0.5) < 1e-12   # sparse factorisation as the solver's
threads = [threading.Thread(target=lambda: np.ones(10**6).sum()) for _ in range(8)]
[t.start() for t in threads]; [t.join() for t in threads]
try:
    np.ones(budget // 8 + 1)
except MemoryError:
    print("MemoryError")
"""


def test_an_allocation_over_the_budget_is_a_memory_error():
    done = subprocess.run([sys.executable, "-c", CHILD], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["MemoryError"]


PREPARED_CHILD = """
import os, resource
os.environ["HAIRPORT_MEMORY_BUDGET_BYTES"] = str(6 * 1024**3)
os.environ["HAIRPORT_WORKER_NICENESS"] = "7"
from hairport.worker import tasks
before = os.getpriority(os.PRIO_PROCESS, 0)
tasks._limit_child()
print(os.getpriority(os.PRIO_PROCESS, 0) - before, resource.getrlimit(resource.RLIMIT_DATA)[0])
"""


def test_a_worker_child_gets_the_memory_budget_and_the_niceness():
    done = subprocess.run([sys.executable, "-c", PREPARED_CHILD], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["7", str(6 * 1024**3)]
