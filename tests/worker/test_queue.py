"""Sending tasks by name over a real (in-memory) broker."""

from hairport.settings import Settings
from hairport.worker.app import MEMORY_BROKER, PREPROCESS_QUEUE, RETARGET_QUEUE, RETARGET_TASK, make_celery
from hairport.worker.queue import TaskQueue


def received(celery, queue: str) -> list[tuple[str, list, dict]]:
    """The (task name, args, kwargs) of the messages waiting on ``queue``."""
    messages = []
    with celery.connection_for_read() as connection:
        simple = connection.SimpleQueue(queue)
        while simple.qsize():
            message = simple.get(timeout=1)
            messages.append((message.headers["task"], message.payload[0], message.payload[1]))
            message.ack()
        simple.close()
    return messages


def test_tasks_are_sent_by_name_to_their_queues():
    celery = make_celery(Settings(), MEMORY_BROKER, deployment="d1")
    queue = TaskQueue(celery)
    task_id = queue.send_retarget("a" * 32)
    assert queue.send_retarget("e" * 32, "chosen-id") == "chosen-id"
    queue.send_preprocess("b" * 32, {"k": 5, "guides": 10})
    queue.send_preprocess("c" * 32)
    assert len(task_id) == 36
    # every task names its deployment, on the deployment's own queues
    mine = {"deployment": "d1"}
    assert received(celery, "hairport.d1." + RETARGET_QUEUE) == [(RETARGET_TASK, ["a" * 32], mine),
                                                                 (RETARGET_TASK, ["e" * 32], mine)]
    assert received(celery, "hairport.d1." + PREPROCESS_QUEUE) == [
        ("hairport.preprocess", ["b" * 32, {"k": 5, "guides": 10}], mine), ("hairport.preprocess", ["c" * 32, None], mine)]
    assert received(celery, RETARGET_QUEUE) == []
    assert queue.task_ids_in_broker() is None and queue.depths() == {} and queue.broker == "memory"


def test_revoking_is_one_broadcast_and_a_broker_that_is_down_is_logged_not_raised(redis_url, tmp_path, caplog):
    from ..conftest import free_port

    settings = Settings(storage_dir=tmp_path, redis_url=redis_url, enqueue_timeout_seconds=0.5)
    assert TaskQueue(make_celery(settings)).revoke("t-1", "t-2") is True
    down = TaskQueue(make_celery(settings, f"redis://127.0.0.1:{free_port()}/0"))
    with caplog.at_level("WARNING", logger="hairport.worker.queue"):
        assert down.revoke() is True  # nothing to revoke: the broker is not asked
        assert caplog.records == []
        assert down.revoke("t-1", "t-2") is False
    assert [record.getMessage().split(" not revoked")[0] for record in caplog.records] == ["tasks t-1, t-2"]
