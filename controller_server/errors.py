"""Errors raised by the controller server, each mapping to a wire error code."""

from __future__ import annotations

from protocol.errors import ErrorCode, ProtocolError

__all__ = ["FrameNotFound", "InvalidParams", "ModelError"]


class ModelError(ProtocolError):
    """A robot model could not be found, parsed or used."""

    def __init__(self, detail: str, *, not_found: bool = False, field: str = "model"):
        code = ErrorCode.MODEL_NOT_FOUND if not_found else ErrorCode.MODEL_INVALID
        super().__init__(code, field, detail)


class FrameNotFound(ModelError):
    """A contact names a frame the model does not have."""

    def __init__(self, name: str, available: list[str]):
        self.name = name
        self.available = available
        super().__init__(
            f"frame {name!r} not in model; available: {', '.join(available)}",
            field="contacts",
        )


class InvalidParams(ProtocolError):
    """A controller parameter is unknown or has a bad value."""

    def __init__(self, field: str, detail: str):
        super().__init__(ErrorCode.INVALID_PARAMS, field, detail)
