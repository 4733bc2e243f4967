"""Pedestrian backends and the robot-conditioned response layer (SPEC §6, paper §III-E).

Backends (registry :data:`BACKENDS`) build the navground behaviour that moves a
pedestrian: ``orca`` (omnidirectional ORCA, 4.5 m horizon) and ``hl`` (Human-like,
5 m horizon). Both get their preferred speed and target from the response layer
only; no Task is attached.

The response layer (:class:`ResponseLayer`) is one numba kernel per step over all
pedestrians. For pedestrian i with profile θ_i = (v, d, a, y, τ, L, g):

* aware once the robot has been within :data:`SENSE_RANGE` for τ_i seconds;
* conflict when, projecting the robot at its current velocity and the pedestrian
  at its intended velocity v_i·e_i over :data:`T_PROJ`, the closest centre
  distance in the future is below r_p + r_r + d_eff, d_eff = d (1 − 0.35 g);
* yielding: during a conflict the preferred speed is v_i (1 − y_i·ramp) with
  ramp = clip((SENSE_RANGE − D)/(SENSE_RANGE − L_i), 0, 1), D the current
  robot distance, so the reduction is complete when the robot reaches L_i; no
  reduction while the robot moves slower than :data:`ROBOT_STOPPED`;
* detour: during a conflict with D ≤ L_i a waypoint 1.5 m ahead along e_i with
  lateral offset Δ_i = clip(a_i·d_eff_i, 0.15, 1.5) m towards the episode's
  passing side. If the waypoint or the midway point lies within r_p + 0.1 m of a
  wall or obstacle the side switches; if both are blocked Δ halves (twice), and
  as a last resort the waypoint is straight ahead. While detouring the speed
  factor is at least :data:`F_DETOUR`. A waypoint ends when reached (0.4 m) or
  after 3 s; then a new one is placed if the conflict persists inside L_i,
  otherwise the route target is restored.

Routes: a pedestrian heads for its via point (beside an obstacle on its lane, see
:mod:`popnavshift.episodes.specs`) until it is ``VIA_LEAD`` before it, then for its
goal 2 m past its exit line. Without a robot the layer only advances routes.

Speed factors are quantised to multiples of 0.05 and written to navground only
when they change; targets are written only on the events above.

The stepping loop (:mod:`popnavshift.sim.run`) does all its per-step array work in
one kernel, :func:`advance`: recorded poses, exit crossings, the robot's goal entry
and the response layer; Python is left with the navground calls.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any, Protocol

import numpy as np
from navground import core, sim
from numba import njit

from ..episodes.specs import PED_RADIUS, VIA_LEAD, EpisodeSpec
from ..registry import Registry

DT = 0.1  # [s] simulation step (robot velocity is a finite difference over one step)
SENSE_RANGE = 6.0  # [m] pedestrians notice the robot within this distance
T_PROJ = 4.0  # [s] constant-velocity projection horizon
G_CLEARANCE = 0.35  # d_eff = d (1 − 0.35 g)
ROBOT_STOPPED = 0.1  # [m/s] robot "nearly stationary" below this speed
WP_AHEAD = 1.5  # [m] waypoint distance ahead along the walking direction
OFFSET_RANGE = (0.15, 1.5)  # [m] bounds of the lateral offset a·d_eff
WP_REACHED = 0.4  # [m] waypoint counts as reached within this distance
WP_TIMEOUT = 3.0  # [s] a waypoint is re-evaluated after this time
WP_TOLERANCE = 0.2  # [m] navground target tolerance of a waypoint (< WP_REACHED)
WP_CLEARANCE = 0.1  # [m] free space beyond r_p a waypoint needs from walls and obstacles
F_DETOUR = 0.3  # lowest speed factor while stepping aside
F_QUANTUM = 0.05  # speed factors are multiples of this
GOAL_TOLERANCE = 0.3  # [m] of a pedestrian's final goal (placed 2 m past its exit)

FLAG_REACTING, FLAG_YIELDING, FLAG_DETOURING = 1, 2, 4


class PedestrianBackend(Protocol):
    """Builds one pedestrian's navground behaviour; ``horizon`` [m] is also its sensing range."""

    @property
    def name(self) -> str: ...

    @property
    def horizon(self) -> float: ...

    def behavior(self, kinematics: core.Kinematics, radius: float) -> core.Behavior: ...

    def describe(self) -> dict[str, Any]: ...


@dataclass(frozen=True)
class ORCABackend:
    """Ped-ORCA: navground ORCA on omnidirectional kinematics."""

    name: str = "orca"
    horizon: float = 4.5  # [m]; also the sensing range of the pedestrian
    time_horizon: float = 3.0  # [s] vs agents (navground default 10 s is very timid)
    static_time_horizon: float = 1.0  # [s] vs walls and obstacles
    safety_margin: float = 0.05  # [m]

    def behavior(self, kinematics: core.Kinematics, radius: float) -> core.Behavior:
        b = core.behaviors.ORCABehavior(kinematics, radius)
        b.horizon = self.horizon
        b.time_horizon = self.time_horizon
        b.static_time_horizon = self.static_time_horizon
        b.safety_margin = self.safety_margin
        return b

    def describe(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class HLBackend:
    """Ped-HL: navground's Human-like behaviour (Guzzi et al. 2013)."""

    name: str = "hl"
    horizon: float = 5.0  # [m]
    tau: float = 0.5  # [s] velocity relaxation time
    eta: float = 0.5  # [s] speed ≤ free distance / eta
    aperture: float = math.pi / 2  # [rad] search ± this around the heading
    resolution: int = 61  # directions sampled over 2·aperture
    safety_margin: float = 0.05  # [m]

    def behavior(self, kinematics: core.Kinematics, radius: float) -> core.Behavior:
        b = core.behaviors.HLBehavior(kinematics, radius)
        b.horizon = self.horizon
        b.tau = self.tau
        b.eta = self.eta
        b.aperture = self.aperture
        b.resolution = self.resolution
        b.safety_margin = self.safety_margin
        return b

    def describe(self) -> dict[str, Any]:
        return asdict(self)


BACKENDS: Registry[PedestrianBackend] = Registry(
    "backend", requires=("behavior", "describe"), noun="pedestrian backend",
    hint="a backend class has name, horizon, behavior(kinematics, radius) and describe()")
BACKENDS.register("orca", ORCABackend)
BACKENDS.register("hl", HLBackend)


def make_pedestrian(
    backend: PedestrianBackend,
    position: tuple[float, float],
    target: tuple[float, float],
    speed: float,
    radius: float,
    agent_id: int,
) -> sim.Agent:
    """A pedestrian agent already walking towards ``target`` at ``speed`` [m/s].

    It gets its own kinematics (max speed = ``speed``) and starts with that velocity,
    so backends with a velocity relaxation (HL) do not spend the first second
    accelerating.
    """
    kin = core.kinematics.OmnidirectionalKinematics(max_speed=speed, max_angular_speed=10.0)
    b = backend.behavior(kin, radius)
    b.optimal_speed = speed
    b.heading_behavior = core.Behavior.Heading.velocity
    se = sim.state_estimations.BoundedStateEstimation(range=backend.horizon)
    agent = sim.Agent(radius=radius, behavior=b, kinematics=kin, state_estimations=[se])
    heading = math.atan2(target[1] - position[1], target[0] - position[0])
    agent.pose = core.Pose2(position, heading)
    velocity = (speed * math.cos(heading), speed * math.sin(heading))
    agent.twist = core.Twist2(velocity, 0.0, frame=core.Frame.absolute)
    agent.last_cmd = agent.twist  # HL relaxes from the last command
    agent.id = agent_id
    agent.type = "pedestrian"
    b.target = core.Target.Point(target, GOAL_TOLERANCE)
    return agent


def effective_clearance(d: np.ndarray, g: np.ndarray) -> np.ndarray:
    """d_eff = d (1 − 0.35 g) [m]."""
    return d * (1.0 - G_CLEARANCE * g)


class ResponseLayer:
    """Per-pedestrian route and response state, and the navground writes they cause.

    ``profiles`` is (n, 7) in :data:`popnavshift.tables.PARAMS` order. Without a
    robot the layer only advances routes (via point → goal).

    The state lives in a few 2-D arrays (numba checks every argument's type on each
    call, ~0.1 us per argument, and the kernel runs every step): :attr:`prm`
    (n, 10) the fixed per-pedestrian values (:data:`PRM`), :attr:`fst` (n, 5) the
    float state (:data:`FST`), :attr:`ist` (n, 3) the integer state (:data:`IST`),
    :attr:`buf` (4, n) the kernel's index lists (exits crossed, speed changes,
    target changes, target codes).
    """

    def __init__(self, behaviors, spec: EpisodeSpec, profiles, robot_radius: float) -> None:
        n = len(behaviors)
        self.behaviors = behaviors
        self.route_targets = [  # stage 0: via point, stage 1: goal
            [core.Target.Point(tuple(p), GOAL_TOLERANCE) for p in points]
            for points in (spec.ped_vias, spec.ped_goals)
        ]
        rows = np.asarray(profiles, np.float64).reshape(n, 7).T
        v, d, a, y, tau, L, g = rows
        deff = effective_clearance(d, g)
        E = np.asarray(spec.ped_directions, dtype=np.float64).reshape(n, 2)
        vias = np.asarray(spec.ped_vias, np.float64).reshape(n, 2)
        self.prm = np.ascontiguousarray(np.column_stack([
            v, deff, np.clip(a * deff, *OFFSET_RANGE), y, tau, L, E,
            np.einsum("ij,ij->i", vias, E) - VIA_LEAD,
            np.asarray(spec.ped_exits, np.float64).reshape(n)]))
        self.fst = np.zeros((n, len(FST)))
        self.fst[:, FST.index("seen")] = np.nan
        self.fst[:, FST.index("factor")] = 1.0
        self.ist = np.zeros((n, len(IST)), np.int64)
        self.buf = np.zeros((4, n), np.int64)
        self.v = self.prm[:, 0]
        self.factor = self.fst[:, FST.index("factor")]
        self.wp = self.fst[:, 1:3]
        self.stage = self.ist[:, IST.index("stage")]
        self.flags = self.ist[:, IST.index("flags")]
        walls = np.asarray(spec.walls, dtype=np.float64).reshape(-1, 4)
        obstacles = np.asarray(spec.obstacles, dtype=np.float64).reshape(-1, 3)
        r_sum, side = PED_RADIUS + robot_radius, int(spec.passing_side)
        need = PED_RADIUS + WP_CLEARANCE
        #: the response kernel's arguments after the per-step ones; the kernel
        #: updates the state arrays in place
        self.state = (self.prm, self.fst, self.ist, self.buf, r_sum, side, need, walls, obstacles)
        #: the same for :func:`advance`, the three scalars packed in one array (a
        #: kernel call costs ~0.08 us per argument, and the loop calls it every step)
        self.packed_state = (self.prm, self.fst, self.ist, self.buf,
                             np.array([r_sum, side, need]), walls, obstacles)

    def step(self, t: float, P: np.ndarray, active: np.ndarray, R: np.ndarray,
             R_prev: np.ndarray, robot_on: bool) -> None:
        """Update the state at time ``t`` [s] and write the changes to navground.

        ``P`` (n, 2) pedestrian positions, ``active`` (n,) not yet arrived, ``R`` and
        ``R_prev`` (2,) robot positions now and one step before, ``robot_on`` robot in
        the scene.
        """
        self.write(*_respond(t, P, active, R, R_prev, robot_on, *self.state))

    def write(self, n_speed: int, n_target: int) -> None:
        """Write to navground the first ``n_speed`` speed and ``n_target`` target
        changes listed by the last kernel call (:meth:`step` or :func:`advance`)."""
        buf = self.buf
        for k in range(n_speed):
            i = buf[1, k]
            self.behaviors[i].optimal_speed = float(self.v[i] * self.factor[i])
        for k in range(n_target):
            i = buf[2, k]
            if buf[3, k] == 1:
                wp = self.wp[i]
                self.behaviors[i].target = core.Target.Point((wp[0], wp[1]), WP_TOLERANCE)
            else:
                self.behaviors[i].target = self.route_targets[self.stage[i]][i]


#: columns of ResponseLayer.prm, .fst and .ist
PRM = ("v", "deff", "offset", "y", "tau", "L", "ex", "ey", "via_line", "exit")
FST = ("seen", "wp_x", "wp_y", "wp_t0", "factor")
IST = ("mode", "stage", "flags")


@njit(cache=True)
def _clear(qx, qy, need, walls, obstacles):
    """Whether point q is at least ``need`` from every wall and obstacle surface."""
    for k in range(walls.shape[0]):
        ax, ay, bx, by = walls[k, 0], walls[k, 1], walls[k, 2], walls[k, 3]
        dx, dy = bx - ax, by - ay
        ll = dx * dx + dy * dy
        s = 0.0 if ll == 0.0 else min(1.0, max(0.0, ((qx - ax) * dx + (qy - ay) * dy) / ll))
        if math.hypot(qx - ax - s * dx, qy - ay - s * dy) < need:
            return False
    for k in range(obstacles.shape[0]):
        if math.hypot(qx - obstacles[k, 0], qy - obstacles[k, 1]) < need + obstacles[k, 2]:
            return False
    return True


@njit(cache=True)
def _waypoint(px, py, ex, ey, side, offset, need, walls, obstacles, out):
    """Write into ``out`` the lateral waypoint; prefer ``side``, switch if blocked, then shrink."""
    lx, ly = -ey, ex  # left of the walking direction
    scale = 1.0
    for _ in range(3):
        for s in (side, -side):
            dx = WP_AHEAD * ex + s * scale * offset * lx
            dy = WP_AHEAD * ey + s * scale * offset * ly
            if _clear(px + dx, py + dy, need, walls, obstacles) and _clear(
                px + 0.5 * dx, py + 0.5 * dy, need, walls, obstacles
            ):
                out[0], out[1] = px + dx, py + dy
                return
        scale *= 0.5
    out[0], out[1] = px + WP_AHEAD * ex, py + WP_AHEAD * ey


@njit(cache=True, inline="always")
def _respond(t, P, active, R, R_prev, robot_on, prm, fst, ist, buf, r_sum, side, need, walls,
             obstacles):
    n_speed = 0
    n_target = 0
    vrx, vry = (R[0] - R_prev[0]) / DT, (R[1] - R_prev[1]) / DT
    robot_slow = math.hypot(vrx, vry) < ROBOT_STOPPED
    for i in range(P.shape[0]):
        ist[i, 2] = 0
        if not active[i]:
            continue
        v, deff, offset, y, tau, L, ex, ey = (prm[i, 0], prm[i, 1], prm[i, 2], prm[i, 3],
                                              prm[i, 4], prm[i, 5], prm[i, 6], prm[i, 7])
        px, py = P[i, 0], P[i, 1]
        dist = math.hypot(R[0] - px, R[1] - py)
        aware = False
        if robot_on and dist <= SENSE_RANGE:
            if math.isnan(fst[i, 0]):
                fst[i, 0] = t
            aware = t - fst[i, 0] >= tau - 1e-9
        else:
            fst[i, 0] = np.nan
        conflict = False
        if aware:
            rx, ry = R[0] - px, R[1] - py
            wx, wy = vrx - v * ex, vry - v * ey
            ww = wx * wx + wy * wy
            if ww > 1e-12:
                ts = min(T_PROJ, -(rx * wx + ry * wy) / ww)
                if ts > 0.0:
                    conflict = math.hypot(rx + wx * ts, ry + wy * ts) < r_sum + deff
        f = 1.0
        if conflict and not robot_slow:
            ramp = min(1.0, max(0.0, (SENSE_RANGE - dist) / (SENSE_RANGE - L)))
            f = 1.0 - y * ramp
        code = 0
        if ist[i, 1] == 0 and px * ex + py * ey >= prm[i, 8]:
            ist[i, 1] = 1  # past the via point: head for the goal
            code = 2
        if ist[i, 0] == 1:
            dw = math.hypot(fst[i, 1] - px, fst[i, 2] - py)
            code = 0  # a detour keeps its waypoint until it ends
            if dw < WP_REACHED or t - fst[i, 3] >= WP_TIMEOUT - 1e-9:
                if conflict and dist <= L:
                    code = 1
                else:
                    ist[i, 0] = 0
                    code = 2
        elif conflict and dist <= L:
            ist[i, 0] = 1
            code = 1
        if code == 1:
            _waypoint(px, py, ex, ey, side, offset, need, walls, obstacles, fst[i, 1:3])
            fst[i, 3] = t
        if code != 0:
            buf[2, n_target] = i
            buf[3, n_target] = code
            n_target += 1
        if ist[i, 0] == 1:
            f = max(f, F_DETOUR)
        fq = round(f / F_QUANTUM) * F_QUANTUM
        if fq != fst[i, 4]:
            fst[i, 4] = fq
            buf[1, n_speed] = i
            n_speed += 1
        ist[i, 2] = (FLAG_REACTING if conflict else 0) | (FLAG_YIELDING if fq < 1.0 else 0) | (
            FLAG_DETOURING if ist[i, 0] == 1 else 0
        )
    return n_speed, n_target


@njit(cache=True, inline="always")
def crossed_exit(P, Pprev, E, exits, active, idx_out, frac_out):
    """Pedestrians that crossed their exit line this step: count, indices, step fraction.

    A pedestrian has left the scene once ``P·e ≥ exit``; ``frac_out`` is the fraction
    of the step's displacement done before the crossing (linear interpolation).
    """
    count = 0
    for i in range(P.shape[0]):
        if not active[i]:
            continue
        now = P[i, 0] * E[i, 0] + P[i, 1] * E[i, 1]
        if now >= exits[i]:
            before = Pprev[i, 0] * E[i, 0] + Pprev[i, 1] * E[i, 1]
            frac = 1.0 if now <= before else (exits[i] - before) / (now - before)
            idx_out[count] = i
            frac_out[count] = min(1.0, max(0.0, frac))
            count += 1
    return count


@njit(cache=True, inline="always")
def entry_fraction(x0, y0, x1, y1, cx, cy, radius):
    """First s ∈ [0, 1] at which the step (x0, y0) → (x1, y1) [m] enters the disc of
    centre (cx, cy) and ``radius`` [m]; 0 if it starts inside, −1 if it never enters."""
    fx, fy, dx, dy = x0 - cx, y0 - cy, x1 - x0, y1 - y0
    c = fx * fx + fy * fy - radius * radius
    if c <= 0.0:
        return 0.0
    dd = dx * dx + dy * dy
    half_b = fx * dx + fy * dy
    disc = half_b * half_b - dd * c
    if dd == 0.0 or disc < 0.0:
        return -1.0
    s = (-half_b - math.sqrt(disc)) / dd
    return s if 0.0 <= s <= 1.0 else -1.0


@njit(cache=True, inline="always")
def advance(step, poses, pos, robot_on, robot_active, goal, active, fracs, arrival_step, prm, fst,
            ist, buf, consts, walls, obstacles):
    """The stepping loop's array work after navground step ``step`` (time step·DT [s]).

    In order: copy x, y of ``poses`` (agents, 3), the step's float32 record, into
    ``pos[step]`` ((steps + 1, agents, 2) [m], robot last); mark the pedestrians that
    crossed their exit (``active`` False, ``arrival_step`` and ``fracs[1]`` (n,) the
    step and its fraction set, indices in ``buf[0, :k]``; ``fracs[0]`` is scratch);
    if ``robot_active``, test whether the robot entered the goal disc (``goal`` (3,):
    x, y, radius), and if so treat it as gone; run the response layer (at the origin
    when the robot is not in the scene). The arguments from ``prm`` on are
    :attr:`ResponseLayer.packed_state`. Few, packed arguments: the call's cost grows
    with their number, and the loop makes it every step.

    Returns (k, goal-entry fraction of the step or −1, n_speed, n_target); the last
    two are for :meth:`ResponseLayer.write`.
    """
    n = active.shape[0]
    for a in range(poses.shape[0]):
        pos[step, a, 0] = poses[a, 0]
        pos[step, a, 1] = poses[a, 1]
    now, before = pos[step], pos[step - 1]
    idx = buf[0]
    frac, arrival_frac = fracs[0], fracs[1]
    k = crossed_exit(now[:n], before[:n], prm[:, 6:8], prm[:, 9], active, idx, frac)
    for j in range(k):
        active[idx[j]] = False
        arrival_step[idx[j]] = step
        arrival_frac[idx[j]] = frac[j]
    s = -1.0
    if robot_active:
        s = entry_fraction(before[n, 0], before[n, 1], now[n, 0], now[n, 1], goal[0], goal[1],
                           goal[2])
        robot_on = robot_on and s < 0.0
    if robot_on:
        n_speed, n_target = _respond(step * DT, now[:n], active, now[n], before[n], robot_on,
                                     prm, fst, ist, buf, consts[0], np.int64(consts[1]),
                                     consts[2], walls, obstacles)
    else:
        origin = np.zeros(2)
        n_speed, n_target = _respond(step * DT, now[:n], active, origin, origin, robot_on,
                                     prm, fst, ist, buf, consts[0], np.int64(consts[1]),
                                     consts[2], walls, obstacles)
    return k, s, n_speed, n_target
