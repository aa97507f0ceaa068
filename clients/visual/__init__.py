"""Seeing a run: the robot posed in MuJoCo, its overlays, video files and the live view."""

__all__: list[str] = []
