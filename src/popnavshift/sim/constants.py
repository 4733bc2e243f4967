"""The simulation's fixed quantities, declared once (SPEC §5–6).

Every module of :mod:`popnavshift.sim` (and the analysis, for the time limit)
reads them from here; ``sim.controllers`` re-exports the robot's for controller
plug-ins. The pedestrians' radius belongs to the episode builder, which places
them, and is re-exported here.
"""

from __future__ import annotations

from ..episodes.specs import PED_RADIUS

DT = 0.1  # [s] simulation step (robot velocity is a finite difference over one step)
MAX_STEPS = 450  # steps of the 45 s episode limit
TIME_LIMIT = MAX_STEPS * DT  # [s] the limit; travel time of a failed robot run
V_STOP = 0.05  # [m/s] an agent moving slower than this is stopped

ROBOT_RADIUS = 0.35  # [m]
WHEEL_AXIS = 0.5  # [m]
ROBOT_SENSING_RANGE = 6.0  # [m], same for every controller
ROBOT_GOAL_TOLERANCE = 0.3  # [m] the robot succeeds within this distance of its goal
PED_GOAL_TOLERANCE = 0.3  # [m] of a pedestrian's final goal (placed 2 m past its exit)

__all__ = ["DT", "MAX_STEPS", "PED_GOAL_TOLERANCE", "PED_RADIUS", "ROBOT_GOAL_TOLERANCE",
           "ROBOT_RADIUS", "ROBOT_SENSING_RANGE", "TIME_LIMIT", "V_STOP", "WHEEL_AXIS"]
