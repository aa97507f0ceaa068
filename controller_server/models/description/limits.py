"""What reading a robot file refuses: its errors, and the caps on what a model may cost.

A model that cannot be used as written raises :class:`DescriptionError`, whose message says
what to change; one over a cap (the ``MAX_*`` constants) raises :class:`DescriptionLimitError`;
a contact naming a frame the model lacks, :class:`FrameNotFoundError`.
"""

from __future__ import annotations

from protocol.errors import did_you_mean

__all__ = [
    "MAX_ASSET_BYTES",
    "MAX_BODIES",
    "MAX_DOF",
    "MAX_IMAGE_PIXELS",
    "MAX_INCLUDE_DEPTH",
    "MAX_PACKAGE_SEARCH_DEPTH",
    "MAX_XML_DEPTH",
    "MAX_XML_ELEMENTS",
    "DescriptionError",
    "DescriptionLimitError",
    "FrameNotFoundError",
    "check_size",
]

MAX_INCLUDE_DEPTH = 16
"""Deepest chain of includes followed."""
MAX_PACKAGE_SEARCH_DEPTH = 8
"""Deepest directory below a ``ROS_PACKAGE_PATH`` entry searched for a package."""

# Caps on what reading a model may cost, so that a file sent by a client cannot
# hold a server worker for long (issue 32). Each is several times what real
# robots need; the numbers measured are in docs/serving.md.
MAX_XML_DEPTH = 128
"""Deepest nesting of elements in a model's XML, includes inlined (a humanoid MJCF: ~20)."""
MAX_XML_ELEMENTS = 20_000
"""Elements of a model's XML, includes inlined, those inside ``<replicate>``,
``<composite>`` and ``<flexcomp>`` counted as often as they repeat (a vendor
humanoid MJCF: a few hundred to 2,000)."""
MAX_BODIES = 500
"""Bodies of a compiled MJCF (robot, props and world), links of a URDF."""
MAX_DOF = 200
"""Degrees of freedom of a model (``nv``, a free base's 6 included): Talos has 38, a
humanoid with two dexterous hands about 90. Loading took 0.6 s at 198 and 13–19 s at
398, a ``prioritized`` tick 24 ms and 0.4–0.9 s (docs/serving.md)."""
MAX_ASSET_BYTES = 64 * 1024 * 1024
"""Bytes of the files a model's meshes, textures, height fields and skins read, a file
counted each time it is named (MuJoCo compiles each naming): ~3 s of compiling."""
MAX_IMAGE_PIXELS = 64 * 1024 * 1024
"""Pixels of a model's textures and height fields together (PNG files' and built-in
ones): a small PNG file may decode into gigabytes."""


class DescriptionError(ValueError):
    """The model cannot be used as written; the message says what to change, on one line.

    Attributes:
        field: What to change: ``model`` (the file), ``contacts`` or ``keyframe``.
    """

    def __init__(self, message: str, *, field: str = "model"):
        super().__init__(message)
        self.field = field


class DescriptionLimitError(DescriptionError):
    """The model exceeds a cap on what reading or serving it may cost (the ``MAX_*`` constants)."""


class FrameNotFoundError(DescriptionError):
    """A contact names a frame the model does not have."""

    def __init__(self, frame: str, available: list[str]):
        self.frame = frame
        self.available = available
        hint = did_you_mean(frame, available)
        super().__init__(
            f"no frame {frame!r} in the model; {hint}frames: {', '.join(available)}",
            field="contacts",
        )


def check_size(bodies: int, dofs: int, what: str) -> None:
    """Refuse a model of more than :data:`MAX_BODIES` bodies or :data:`MAX_DOF` DoF.

    Raises:
        DescriptionLimitError: Over either cap.
    """
    if bodies > MAX_BODIES:
        raise DescriptionLimitError(f"the model has {bodies} {what}; at most {MAX_BODIES}")
    if dofs > MAX_DOF:
        raise DescriptionLimitError(
            f"the model has {dofs} degrees of freedom (nv, the free base's 6 included); at "
            f"most {MAX_DOF}"
        )
