"""A robot as its vendor's file describes it: one reading shared by the server and the simulators.

MJCF goes through MuJoCo's own compiler, which resolves what vendors write:
robot files ``<include>``-ed by a ``scene.xml``, ``<default>`` classes,
both free-joint spellings, meshes, ``autolimits``, extra root bodies
(cameras, mocap targets, props). The Pinocchio model is then built from the
*compiled* MuJoCo model, body by body, so the server's dynamics are the
simulator's to the last inertia. URDF is read by Pinocchio's parser.

:func:`describe` never opens a file: every ``<include>``, asset, URDF mesh
and SRDF goes through a ``read`` callable (the server's confines reads to its
model directories, a client-sent model reads only the files it sent), and
MuJoCo compiles from memory, so it cannot open a file the caller did not hand
over. The readers find what a name stands for with :func:`resolve_file`
(``package://`` URIs as ROS tools find them, :func:`find_package`).

From the model, a :class:`RobotDescription` finds:

* **Contacts.** ``*_sole`` box sites if the file has them (the corners of the
  site's x–y rectangle, as the built-in robots); otherwise the feet are found
  from the collision geometry: at the standing pose, the bodies whose
  collision geoms reach within :data:`FOOT_HEIGHT_TOLERANCE_M` of the lowest
  point are the feet (a foot's descendants are part of it), and each foot's
  sole is the rectangle, aligned with the foot's heading, around its
  collision points within :data:`SOLE_HEIGHT_TOLERANCE_M` of its lowest one.
  A contact may instead be named (a frame without points): its sole is found
  the same way from that frame's body and its descendants. A URDF collision
  mesh that cannot be read is left out (one warning for all of them), unless
  a sole is looked for on its link (a :func:`foot_candidates` link, or a
  named foot): then it is an error, not a silent choice of other feet.
* **Torque limits** from every place a file states them: MJCF actuator
  ``forcerange``, a motor's ``ctrlrange`` × gain, × |gear|, and the joint's
  ``actuatorfrcrange`` (defaults classes included, being compiled); URDF
  ``<limit effort>``.
* **Actuator kinds** per joint (``motor``, ``position``, ``velocity``,
  ``general``, or ``none``), so that a simulator can convert
  position-actuated models to torque motors instead of misusing them.
* **The standing pose**: a keyframe by name (MJCF ``<key>``; a URDF's SRDF
  ``group_state``), or the file's reference pose, lifted or lowered so that
  the lowest contact point is at z = 0.
* **Disabled collision pairs** from a URDF's SRDF (``disable_collisions``).

The package's modules, each imported only by those after it: ``limits`` (the errors and
the ``MAX_*`` caps), ``files`` (where a named file is), ``mjcf`` (MJCF expanded and
compiled by MuJoCo), ``shapes`` (collision geometry as points), ``bodies`` (what a reader
makes of a robot), ``feet`` (contacts from geometry), ``pinocchio_from_mujoco`` (an MJCF's
robot in Pinocchio), ``srdf``, ``urdf``, and ``robot`` (:class:`RobotDescription`,
:func:`describe`, :func:`gather_files`).
"""

from controller_server.models.description.bodies import FoundContact
from controller_server.models.description.feet import (
    FOOT_CANDIDATE_HEIGHT_FRACTION,
    FOOT_HEIGHT_TOLERANCE_M,
    SOLE_HEIGHT_TOLERANCE_M,
    foot_candidates,
    subtree,
)
from controller_server.models.description.files import (
    FileReader,
    find_package,
    resolve_file,
    ros_package_path,
)
from controller_server.models.description.limits import (
    MAX_ASSET_BYTES,
    MAX_BODIES,
    MAX_DOF,
    MAX_IMAGE_PIXELS,
    MAX_PACKAGE_SEARCH_DEPTH,
    MAX_XML_DEPTH,
    MAX_XML_ELEMENTS,
    DescriptionError,
    DescriptionLimitError,
    FrameNotFoundError,
)
from controller_server.models.description.mjcf import compile_mjcf, expand_mjcf
from controller_server.models.description.robot import RobotDescription, describe, gather_files
from controller_server.models.description.srdf import srdf_paths

__all__ = [
    "FOOT_CANDIDATE_HEIGHT_FRACTION",
    "FOOT_HEIGHT_TOLERANCE_M",
    "MAX_ASSET_BYTES",
    "MAX_BODIES",
    "MAX_DOF",
    "MAX_IMAGE_PIXELS",
    "MAX_PACKAGE_SEARCH_DEPTH",
    "MAX_XML_DEPTH",
    "MAX_XML_ELEMENTS",
    "SOLE_HEIGHT_TOLERANCE_M",
    "DescriptionError",
    "DescriptionLimitError",
    "FileReader",
    "FoundContact",
    "FrameNotFoundError",
    "RobotDescription",
    "compile_mjcf",
    "describe",
    "expand_mjcf",
    "find_package",
    "foot_candidates",
    "gather_files",
    "resolve_file",
    "ros_package_path",
    "srdf_paths",
    "subtree",
]
