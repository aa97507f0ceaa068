"""Issue 32, finding 6: nothing of a request outlives its reply (a worker grew 182 → 813 MB).

The codec's fast path raised one ``Fallback`` instance for every payload it handed to
pydantic, and every raise added that request's frames (its bytes, decoded map and
reply) to the instance's traceback, for good.
"""

import gc
import types

import numpy as np

from controller_server.session_table import SessionTable
from protocol import decode, encode
from protocol.messages import Hello, Welcome
from tests.e2e.test_fuzz_server import _mutate


def frames_of_requests() -> int:
    """Frames of the table's request handling still alive (held by some traceback)."""
    names = {"_answer", "handle", "decode"}
    return sum(
        isinstance(o, types.FrameType) and o.f_code.co_name in names for o in gc.get_objects()
    )


def test_mutated_requests_leave_no_frames_alive():
    table = SessionTable(tick_budget_s=None)
    welcome = decode(encode(table.handle(b"k", encode(Hello(seq=1, model="thesis_humanoid")))))
    assert isinstance(welcome, Welcome)
    rng = np.random.default_rng(0)
    for seq in range(2, 300):
        table.handle(b"k", _mutate(rng, welcome, seq))
        table.handle(b"no session", _mutate(rng, welcome, seq))  # as the broker's own table
    gc.collect()
    assert frames_of_requests() == 0
