"""Sending tasks by name over a real (in-memory) broker."""

from hairport.settings import Settings
from hairport.worker.app import MEMORY_BROKER, PREPROCESS_QUEUE, RETARGET_QUEUE, RETARGET_TASK, make_celery
from hairport.worker.queue import TaskQueue


def received(celery, queue: str) -> list[tuple[str, list]]:
    """The (task name, args) of the messages waiting on ``queue``."""
    messages = []
    with celery.connection_for_read() as connection:
        simple = connection.SimpleQueue(queue)
        while simple.qsize():
            message = simple.get(timeout=1)
            messages.append((message.headers["task"], message.payload[0]))
            message.ack()
        simple.close()
    return messages


def test_tasks_are_sent_by_name_to_their_queues():
    celery = make_celery(Settings(), MEMORY_BROKER)
    queue = TaskQueue(celery)
    task_id = queue.send_retarget("a" * 32)
    queue.send_preprocess("b" * 32, {"k": 5, "guides": 10})
    queue.send_preprocess("c" * 32)
    assert len(task_id) == 36
    assert received(celery, RETARGET_QUEUE) == [(RETARGET_TASK, ["a" * 32])]
    assert received(celery, PREPROCESS_QUEUE) == [("hairport.preprocess", ["b" * 32, {"k": 5, "guides": 10}]),
                                                  ("hairport.preprocess", ["c" * 32, None])]
