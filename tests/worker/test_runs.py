"""Who runs a job: a dead process (also a zombie) is told from a live one, a heartbeat thread beats and stops."""

import os
import subprocess
import sys
import threading

from hairport.records import RunInfo, now
from hairport.worker import runs


def test_a_process_that_exited_or_is_a_zombie_is_not_alive():
    assert runs.pid_alive(os.getpid())
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    while not os.path.exists(f"/proc/{child.pid}") or open(f"/proc/{child.pid}/stat").read().split(")")[1].split()[0] != "Z":
        pass  # exited, not yet reaped: a zombie
    assert not runs.pid_alive(child.pid)
    child.wait()
    assert not runs.pid_alive(child.pid)


def test_a_run_is_gone_when_silent_or_its_process_on_this_host_is():
    fresh = RunInfo(heartbeat_at=now(), worker_host=runs.HOST, worker_pid=os.getpid())
    assert not runs.run_gone(fresh, 10)
    assert runs.run_gone(fresh.model_copy(update={"heartbeat_at": now() - 11}), 10)
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    assert runs.run_gone(fresh.model_copy(update={"worker_pid": child.pid}), 10)
    # on another host the process cannot be checked: only the heartbeat counts
    assert not runs.run_gone(fresh.model_copy(update={"worker_pid": child.pid, "worker_host": "elsewhere"}), 10)


def test_the_heartbeat_beats_until_the_run_is_not_ours():
    beats = []
    done = threading.Event()

    def beat() -> bool:
        beats.append(now())
        if len(beats) == 3:
            done.set()
            return False
        return True

    with runs.Heartbeat(beat, 0.01) as heartbeat:
        assert done.wait(10)
        heartbeat.thread.join(10)
        assert not heartbeat.thread.is_alive() and len(beats) == 3
