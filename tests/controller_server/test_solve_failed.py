"""Issue 32: a state the controller finds no command for is ``SOLVE_FAILED``, not ``INTERNAL``.

``INTERNAL`` is kept for the server's bugs, and only they leave a traceback in the log;
every error a client's input causes is typed at the edge, without one.
"""

import logging

import numpy as np
import pytest

from clients.client import ServerError
from controller_server import errors
from controller_server.controllers import Controller
from controller_server.controllers.compiled_tick import CompiledWeightedTick
from controller_server.errors import ControllerFailed, ServerFault, wire_code
from controller_server.session_table import SessionTable
from protocol import ErrorCode, decode, encode
from protocol.messages import Command, Error, Hello, Welcome
from tests.helpers import random_state

KEY = b"alice"


def ask(table, message):
    return decode(encode(table.handle(KEY, encode(message))))


def open_session(table, controller: str) -> Welcome:
    welcome = ask(table, Hello(seq=1, model="thesis_humanoid", controller=controller))
    assert isinstance(welcome, Welcome), welcome
    return welcome


def tracebacks(caplog) -> list[logging.LogRecord]:
    return [record for record in caplog.records if record.exc_info]


def test_no_server_fault_is_internal_on_the_wire():
    """Every error the server raises on purpose has a code of its own; INTERNAL is a bug."""
    for name in errors.__all__:
        cls = getattr(errors, name)
        if isinstance(cls, type) and issubclass(cls, ServerFault) and cls is not ServerFault:
            fault = cls.__new__(cls)
            assert wire_code(fault) != ErrorCode.INTERNAL, name
    assert wire_code(ControllerFailed("no command")) == ErrorCode.SOLVE_FAILED


def test_solve_failed_is_its_own_code_with_advice():
    assert ErrorCode.SOLVE_FAILED not in (ErrorCode.INTERNAL, ErrorCode.DEADLINE_EXCEEDED)
    assert "safe behaviour" in ErrorCode.SOLVE_FAILED.description
    assert "bug" in ErrorCode.INTERNAL.description


@pytest.mark.parametrize("controller", ["momentum", "prioritized"])
def test_a_failed_linear_solve_is_solve_failed_without_traceback(controller, monkeypatch, caplog):
    table = SessionTable(tick_budget_s=None)
    welcome = open_session(table, controller)

    def singular(*args, **kwargs):
        raise np.linalg.LinAlgError("Singular matrix")

    # Either kernel: the controllers take their dynamics terms from one method of the base.
    monkeypatch.setattr(Controller, "_dynamics_terms", singular)
    monkeypatch.setattr(CompiledWeightedTick, "compute", singular)  # the compiled tick's
    state = random_state(welcome, np.random.default_rng(0)).model_copy(update={"seq": 7})
    with caplog.at_level(logging.DEBUG):
        reply = ask(table, state)
    assert isinstance(reply, Error), reply
    assert (reply.code, reply.field, reply.seq) == (ErrorCode.SOLVE_FAILED, "controller", 7)
    assert "Singular matrix" in reply.detail
    assert not tracebacks(caplog)
    monkeypatch.undo()
    assert isinstance(ask(table, state), Command)  # the session is kept
    assert table.session_stats()[0].errors == 1


def test_a_spent_qp_time_budget_is_solve_failed_and_the_session_goes_on(monkeypatch, caplog):
    """306 ``INTERNAL`` in the issue-32 fuzz were this, on states inside the documented limits."""
    table = SessionTable(tick_budget_s=None)
    welcome = open_session(table, "prioritized")
    controller = table.sessions[KEY].controller
    original = controller.compute
    calls = []

    def over_budget_once(control_input):
        calls.append(1)
        if len(calls) == 1:
            raise ControllerFailed(
                "the equations of motion could not be solved (failed, QP solver proxqp: QP time "
                "budget of 20 ms spent); no command"
            )
        return original(control_input)

    monkeypatch.setattr(controller, "compute", over_budget_once)
    state = random_state(welcome, np.random.default_rng(1)).model_copy(update={"seq": 3})
    with caplog.at_level(logging.DEBUG):
        reply = ask(table, state)
    assert reply.code == ErrorCode.SOLVE_FAILED and "time budget" in reply.detail
    assert not tracebacks(caplog)
    assert isinstance(ask(table, state), Command)


def test_a_bug_is_still_internal_with_its_traceback(monkeypatch, caplog):
    table = SessionTable(tick_budget_s=None)
    welcome = open_session(table, "momentum")

    def bug(control_input):
        raise KeyError("a bug")

    monkeypatch.setattr(table.sessions[KEY].controller, "compute", bug)
    with caplog.at_level(logging.ERROR):
        reply = ask(table, random_state(welcome, np.random.default_rng(2)))
    assert reply.code == ErrorCode.INTERNAL
    assert len(tracebacks(caplog)) == 1


def test_the_client_raises_solve_failed_as_a_server_error():
    reply = Error(seq=4, code=ErrorCode.SOLVE_FAILED, field="controller", detail="no command")
    error = ServerError.of(decode(encode(reply)), 4)
    assert error.code == ErrorCode.SOLVE_FAILED and "SOLVE_FAILED" in str(error)
