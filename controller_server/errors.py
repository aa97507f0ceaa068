"""The server's own errors; the edge (`session_table`) maps them to wire codes.

Models, files, controllers and sessions raise these, knowing nothing of the
wire: :func:`wire_code` is the one table from an error to the ``error``
message's code. Every one carries the request field it concerns and a
one-line detail.
"""

from __future__ import annotations

from protocol.errors import ErrorCode, PoiseError

__all__ = [
    "ControllerFailed",
    "EstimatorInputError",
    "FileTooLarge",
    "FrameNotFound",
    "ImuFrameError",
    "InvalidParams",
    "ModelError",
    "ModelMismatch",
    "ModelNotFound",
    "ModelTooLarge",
    "ServerFault",
    "TickTooCostly",
    "UnknownController",
    "wire_code",
]


class ServerFault(PoiseError):
    """A request the server cannot serve as asked.

    Attributes:
        field: The request field at fault (``"model"``, ``"params.stiffness"``).
        detail: One line: what is wrong and what would do.
    """

    def __init__(self, field: str, detail: str):
        self.field = field
        self.detail = detail
        super().__init__(f"{field}: {detail}")


class ModelError(ServerFault):
    """A robot model could not be parsed or used."""

    def __init__(self, detail: str, *, field: str = "model"):
        super().__init__(field, detail)


class ModelNotFound(ModelError):
    """No built-in model and no allowed file of that name."""


class ModelMismatch(ModelError):
    """The client expects another model (its ``expected_model_hash`` differs)."""


class ModelTooLarge(ModelError):
    """A model over a cap on what one session may cost the server.

    The caps bound XML nesting and elements, bodies, DoF, contacts and their
    points, and file bytes (docs/serving.md); the detail names the one hit.
    """


class TickTooCostly(ModelTooLarge):
    """A session whose tick, timed at ``hello``, would not fit the server's tick budget."""


class FrameNotFound(ModelError):
    """A contact names a frame the model does not have."""

    def __init__(self, name: str, available: list[str]):
        self.name = name
        self.available = available
        super().__init__(
            f"frame {name!r} not in model; available: {', '.join(available)}", field="contacts"
        )


class InvalidParams(ServerFault):
    """A controller parameter is unknown or has a bad value."""


class UnknownController(ServerFault):
    """No controller has the name a ``hello`` gives."""


class FileTooLarge(ServerFault):
    """A model or clip file exceeds the server's size cap."""


class ControllerFailed(ServerFault):
    """A controller found no command for a valid request; the session is kept.

    Raised instead of numerical exceptions (``LinAlgError``, a solver giving up, its time
    budget spent), with one line saying what failed, so that no tick ends in an untyped
    error. On the wire it is ``SOLVE_FAILED``: the state is the cause, not a bug of the
    server (``INTERNAL``), and the client holds its safe behaviour.
    """

    def __init__(self, detail: str):
        super().__init__("controller", detail)


class EstimatorInputError(ServerFault, ValueError):
    """A base estimator input is missing, misshapen or not finite; the estimate is unchanged."""


class ImuFrameError(ServerFault):
    """``hello.imu_frame`` names no frame of the model, or one not rigid on the root body."""


_WIRE_CODES: dict[type[ServerFault], ErrorCode] = {
    ModelNotFound: ErrorCode.MODEL_NOT_FOUND,
    ModelMismatch: ErrorCode.MODEL_MISMATCH,
    ModelTooLarge: ErrorCode.LIMIT_EXCEEDED,
    ModelError: ErrorCode.MODEL_INVALID,
    InvalidParams: ErrorCode.INVALID_PARAMS,
    UnknownController: ErrorCode.UNKNOWN_CONTROLLER,
    FileTooLarge: ErrorCode.LIMIT_EXCEEDED,
    ControllerFailed: ErrorCode.SOLVE_FAILED,
    EstimatorInputError: ErrorCode.INVALID_FIELD,
    ImuFrameError: ErrorCode.INVALID_FIELD,
}


def wire_code(error: ServerFault) -> ErrorCode:
    """The wire code of ``error``: its class's, or its nearest base's in the table."""
    for cls in type(error).__mro__:
        if cls in _WIRE_CODES:
            return _WIRE_CODES[cls]
    return ErrorCode.INTERNAL
