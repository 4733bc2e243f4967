"""Example PopNavShift plug-in written from scratch: :class:`~go_to_goal.controller.GoToGoal`."""

from .controller import GoToGoal

__all__ = ["GoToGoal"]
