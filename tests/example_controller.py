"""The example controller package (examples/slow_near_peds) and user-written controllers,
as the registry and evaluate tests install them."""

from __future__ import annotations

import tomllib
from pathlib import Path

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "slow_near_peds"

#: Controllers a user might write, imported from a folder put on sys.path.
USER_MODULE = '''
import math
from navground import core


class Sensing(core.Behavior):
    """A behaviour that bounded sensing fills (what the plug-ins below share)."""

    def __init__(self, kinematics=None, radius=0.0):
        core.Behavior.__init__(self, kinematics, radius)
        self._state = core.GeometricState()

    def get_environment_state(self):
        return self._state


class RaisesNearPeds(Sensing, name="TestPluginRaisesNearPeds"):
    """Straight to the goal; raises once a pedestrian is within 1 m of clearance."""

    def compute_cmd_internal(self, time_step):
        x, y = self.position
        for n in self._state.neighbors:
            if math.hypot(n.position[0] - x, n.position[1] - y) - n.radius - self.radius < 1.0:
                raise RuntimeError("a pedestrian is too close")
        return self.cmd_twist_towards_point(self.target.position, self.optimal_speed, time_step)


class Infeasible(Sensing, name="TestPluginInfeasible"):
    def compute_cmd_internal(self, time_step):
        return core.Twist2((5.0, 0.0), 0.0, core.Frame.relative)


class NotABehavior:
    pass
'''


def install_example(root: Path) -> Path:
    """A dist-info for the example package with the entry points its pyproject declares:
    what ``pip install examples/slow_near_peds`` writes, without touching the venv."""
    project = tomllib.loads((EXAMPLE / "pyproject.toml").read_text())["project"]
    info = root / f"{project['name'].replace('-', '_')}-{project['version']}.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text(
        f"Metadata-Version: 2.1\nName: {project['name']}\nVersion: {project['version']}\n")
    lines = []
    for group, eps in project["entry-points"].items():
        lines += [f"[{group}]", *(f"{k} = {v}" for k, v in eps.items()), ""]
    (info / "entry_points.txt").write_text("\n".join(lines))
    return info
