"""What a picture of a log is drawn from: the :class:`~clients.track.Track` of a recorded log.

(A simulator run gives the backend's true states: :func:`clients.sim.runner.track_of_run`.) A
recorded log gives the states its client sent (:func:`track_of_log`), and for
a state that carried an IMU reading instead of the base, the base the server
estimated (its diagnostics' ``base_estimate``, held between diagnostics ticks).
"""

from __future__ import annotations

import os
from pathlib import Path

from clients.replay import read_recorded
from clients.track import Track, session_track
from protocol.messages import Command, State
from protocol.recording import BadLog

__all__ = ["Track", "track_of_log"]


def track_of_log(path: str | os.PathLike[str], model_dir: Path | None = None) -> Track:
    """The track of a log's first session: each answered ``state`` and its command.

    Time is each state's ``time_s`` less the first's. A model the client sent
    as text (``hello.model_text`` and its files) is written to ``model_dir``
    (default: a new temporary directory) so that MuJoCo can load it.

    Raises:
        BadLog: Not a log, no state answered by a command, or a state carrying an
            IMU reading before any diagnostics estimated the base.
        ReplayError: The log holds no handshake.
    """
    session = read_recorded(path).session  # the whole log: corruption anywhere is found
    track = session_track(Path(path).stem, session.hello, session.welcome, "recorded", model_dir)
    for _, request in session.requests:
        reply = session.replies.get(request.seq)
        if not (isinstance(request, State) and isinstance(reply, Command)):
            continue
        if not track.add_exchange(request, reply):
            raise BadLog(
                path,
                f"the state at {request.time_s:.3f} s carries an IMU reading and no "
                "diagnostics estimated the base yet: nothing to draw the robot from",
            )
    if not track.commands:
        raise BadLog(path, "no recorded state was answered by a command: nothing to draw")
    return track
