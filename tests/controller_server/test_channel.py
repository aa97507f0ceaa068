"""The broker ↔ worker link: messages of frames over a Unix socket pair, however they arrive."""

import gc
import socket
import threading
import weakref

import pytest

from controller_server.session_table import release_free_memory
from controller_server.worker import Channel


@pytest.fixture
def pair():
    ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
    broker, worker = Channel(ours, blocking=False), Channel(theirs, blocking=True)
    yield broker, worker
    broker.close()
    worker.close()


def test_messages_keep_their_frames(pair):
    broker, worker = pair
    messages = [[b"req", b"\x00" * 24, b"payload"], [b"drop"], [b"", b"x", b""], [b"stop"]]
    for frames in messages:
        broker.send(frames)
    received = []
    while len(received) < len(messages):
        received += worker.receive()
    assert received == messages
    assert broker.receive() == []  # nothing for the broker: the non-blocking end returns


def test_a_message_arriving_byte_by_byte_is_whole_once_complete(pair):
    broker, worker = pair
    data = Channel.pack([b"rep", b"header", b"reply" * 100])
    for byte in data[:-1]:
        worker.socket.sendall(bytes([byte]))
        assert broker.receive() == []
    worker.socket.sendall(data[-1:])
    assert broker.receive() == [[b"rep", b"header", b"reply" * 100]]


def test_a_message_larger_than_the_socket_buffers_is_flushed_as_it_is_read(pair):
    broker, worker = pair
    big = bytes(range(256)) * (16 * 1024)  # 4 MB: a hello with a model file
    broker.send([b"req", b"h" * 24, big])
    assert broker.outgoing  # the socket took part of it: the rest waits, nothing blocks
    received = []
    reader = threading.Thread(target=lambda: received.extend(worker.receive()))
    reader.start()
    while not broker.flush():
        pass
    reader.join(10)
    assert received == [[b"req", b"h" * 24, big]]


def test_a_closed_end_reads_as_none(pair):
    broker, worker = pair
    broker.close()
    assert worker.receive() is None
    with pytest.raises(OSError):
        for _ in range(100):  # the first writes may still be buffered
            worker.send([b"rep", b"x" * 65536])


class _Cycle:
    def __init__(self):
        self.me = self


def test_freed_memory_includes_what_a_worker_froze():
    """Workers freeze their objects (gc.freeze); a dropped session's cycles are still collected."""
    cycle = _Cycle()
    alive = weakref.ref(cycle)
    gc.freeze()
    try:
        del cycle
        release_free_memory()
        assert alive() is None
        assert gc.get_freeze_count() > 0  # the survivors are frozen again
    finally:
        gc.unfreeze()
