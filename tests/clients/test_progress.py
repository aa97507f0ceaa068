"""The progress bar draws on a terminal only, and clears its line."""

import io

from clients.progress import ProgressBar


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_the_bar_draws_on_a_terminal_and_clears_its_line():
    stream = Terminal()
    with ProgressBar("replay", stream=stream) as bar:
        bar(0.5)
        drawn = stream.getvalue()
    assert drawn.startswith("\rreplay") and "#" * 15 + "." * 15 in drawn and "50%" in drawn
    assert stream.getvalue().endswith("\r") and stream.getvalue().count("\r") == 3


def test_nothing_is_drawn_into_a_pipe_or_when_disabled():
    pipe = io.StringIO()
    with ProgressBar("replay", stream=pipe) as bar:
        bar(0.5)
    quiet = Terminal()
    with ProgressBar("replay", enabled=False, stream=quiet) as bar:
        bar(0.5)
    assert pipe.getvalue() == "" and quiet.getvalue() == ""
