"""A scripted LIBERO expert on privileged simulator state, driving the default OSC_POSE controller.

The plan comes from the task's BDDL goal predicates (`In`/`On` become pick-and-place). Each skill is
a generator that receives the step count and yields 7-dim delta actions (xyz, axis-angle, gripper);
motions are proportional moves towards waypoints computed from current object poses.
"""

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from lerobot_predvla.libero.geometry import SceneView

POS_SCALE = 0.05  # OSC_POSE output_max for xyz (m per action unit)
ROT_SCALE = 0.5  # OSC_POSE output_max for rotation (rad per action unit)
OPEN, CLOSE = -1.0, 1.0
MAX_FINGER_SPAN = 0.075  # wider objects are grasped at their rim
PUSH_LEAN = 0.5  # tan of the gripper's lean back from vertical while pushing
MIN_GRASP_HEIGHT = 0.03  # wide objects flatter than this (plates) are pushed along the table, not picked
HANDLE_WIDTH = 0.03  # a wide object's handle: thinner than this across, grasped instead of a rim
RIM_LEAN = 0.5  # tan of the lean along the rim a rim grasp may take to keep the hand off an overhang
DOWN = np.array([0.0, 0.0, -1.0])
SKILL_ORDER = {"open": 0, "turnon": 0, "in": 1, "on": 1, "close": 2}  # plan order of goal predicates

Skill = Iterator[np.ndarray]


class ExpertFailure(RuntimeError):
    """The expert gave up (no plan for a predicate, or repeated grasp failure)."""


@dataclass
class Target:
    """Where a carried object goes: xy of its centre (of its body origin if `by_origin`), height to clear,
    height of its bottom at release."""

    xy: np.ndarray
    clear_z: float
    release_z: float
    by_origin: bool = False


def _unit(v: np.ndarray) -> np.ndarray:
    return v / (np.linalg.norm(v) + 1e-9)


def _skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrix of `v`: _skew(v) @ x == np.cross(v, x)."""
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def _tilt(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation matrix taking unit vector `a` onto unit vector `b` (Rodrigues)."""
    n, c = np.cross(a, b), float(a @ b)
    k = _skew(n)
    return np.eye(3) + k + k @ k / (1 + c) if c > -0.999 else -np.eye(3)


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation matrix of `angle` about unit vector `axis`."""
    k = _skew(axis)
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def _box_gaps(points: np.ndarray, lows: np.ndarray, highs: np.ndarray) -> np.ndarray:
    """Distance from each of `points` (n, d) to the nearest axis-aligned box (lows, highs: (m, d)); 1 if none."""
    outside = np.maximum(0, np.maximum(lows[None] - points[:, None], points[:, None] - highs[None]))
    return np.linalg.norm(outside, axis=2).min(1, initial=1.0)


def _box_gap(points: np.ndarray, lows: np.ndarray, highs: np.ndarray) -> float:
    """Smallest distance from any of `points` (n, d) to any axis-aligned box (lows, highs: (m, d)); 1 if none."""
    return float(_box_gaps(points, lows, highs).min(initial=1.0))


def _rotation_error(z_now: np.ndarray, f_now: np.ndarray, z_goal: np.ndarray, f_goal: np.ndarray) -> np.ndarray:
    """World-frame axis-angle turning the gripper frame (approach z, finger f) onto the goal frame."""
    now = np.column_stack([f_now, np.cross(z_now, f_now), z_now])
    goal = np.column_stack([f_goal, np.cross(z_goal, f_goal), z_goal])
    r = goal @ now.T
    angle = np.arccos(np.clip((np.trace(r) - 1) / 2, -1.0, 1.0))
    if angle < 1e-6:
        return np.zeros(3)
    axis = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    return _unit(axis) * angle


class ScriptedExpert:
    """Solves LIBERO goals (`In`, `On`, `Open`, `Close`, `Turnon`); call `act()` once per control step."""

    def __init__(self, env, speed: float = 1.0, rng: np.random.Generator | None = None) -> None:
        self.view = SceneView(env)
        self.goal = [tuple(p) for p in env.env.parsed_problem["goal_state"]]
        unsupported = [p for p in self.goal if p[0] not in SKILL_ORDER]
        if unsupported:
            raise ExpertFailure(f"no scripted plan for goal predicates {unsupported}")
        self.speed = speed
        self.rng = rng or np.random.default_rng()
        self._plan = self._run()
        self.done = False

    # Low-level control ---------------------------------------------------------------------------
    def _finger_goal(self, axis: np.ndarray, finger: np.ndarray | None) -> np.ndarray:
        """Goal finger direction: `finger` (xy or 3D) made normal to `axis`, of the sign nearest the current
        one once the gripper is tilted onto `axis`; None keeps the current finger direction."""
        f_now = _tilt(self.view.eef_axis_z(), axis) @ self.view.finger_axis()
        f = f_now if finger is None else np.pad(finger, (0, 3 - len(finger)))
        f = _unit(f - (f @ axis) * axis)
        return f if f @ f_now >= 0 else -f  # a parallel gripper is symmetric under a half turn

    def _rot_error(self, axis: np.ndarray, finger: np.ndarray | None) -> np.ndarray:
        v = self.view
        return _rotation_error(v.eef_axis_z(), v.finger_axis(), axis, self._finger_goal(axis, finger))

    def _action(self, pos: np.ndarray, finger: np.ndarray | None, grip: float, axis: np.ndarray = DOWN,
                max_speed: float = 1.0) -> np.ndarray:
        """Proportional step towards `pos`, gripper approach axis onto `axis`, fingers along `finger`."""
        dpos = np.clip((pos - self.view.eef_pos()) / POS_SCALE * 2.0, -max_speed, max_speed) * self.speed
        drot = np.clip(self._rot_error(axis, finger) * 2.0 / ROT_SCALE, -1, 1)
        return np.concatenate([dpos, drot, [grip]])

    def _move(self, goal, grip: float, tol: float = 0.01, max_steps: int = 60, max_speed: float = 1.0,
              axis: np.ndarray = DOWN) -> Skill:
        """Move until within `tol` of goal() -> (pos, finger); goal is re-evaluated every step."""
        for _ in range(max_steps):
            pos, finger = goal()
            if np.linalg.norm(pos - self.view.eef_pos()) < tol and (
                    finger is None or np.linalg.norm(self._rot_error(axis, finger)) < 0.08):
                return
            yield self._action(pos, finger, grip, axis, max_speed=max_speed)

    def _hold(self, grip: float, steps: int, finger: np.ndarray | None = None, axis: np.ndarray = DOWN) -> Skill:
        pos = self.view.eef_pos()
        for _ in range(steps):
            yield self._action(pos, finger, grip, axis)

    # Skills ----------------------------------------------------------------------------------------
    def _grasp_pose(self, name: str, radial: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        """Fingertip target and finger direction for a top-down grasp of object `name`.

        With a `radial` direction (objects wider than the fingers' span, e.g. bowls) the grasp is at
        the rim point along it; the choice is made once per attempt by `_rim_grasp`.
        """
        box = self.view.box(name)
        handle = self._handle(name) if box.short > MAX_FINGER_SPAN else None
        if handle is not None:  # fingers across the handle's thin side
            out = _unit(handle[:2] - self.view.body_pos(name)[:2])
            return handle, np.array([-out[1], out[0]])
        if radial is None:
            # Narrow side between the fingers; round objects keep the current yaw.
            yaw = box.short_dir if box.long - box.short > 0.01 else None
            z = max(box.bottom + box.height / 2, box.top - 0.035)
            return np.array([box.center[0], box.center[1], z]), yaw
        xy = box.center[:2] + radial * (box.short / 2 - 0.012)
        return np.array([xy[0], xy[1], box.top - 0.02]), radial

    def _handle(self, name: str) -> np.ndarray | None:
        """Top centre of the handle of a wide object (a moka pot): its collision geom reaching furthest from
        the object's origin, if that is thinner than HANDLE_WIDTH across and reaches 2 cm beyond every geom
        pointing elsewhere; None otherwise (bowls and boxes)."""
        v = self.view
        lows, highs = v.geom_boxes(name)
        out = (lows + highs)[:, :2] / 2 - v.body_pos(name)[:2]
        reach = np.linalg.norm(np.stack([lows[:, :2], highs[:, :2]], 1) - v.body_pos(name)[:2], axis=2).max(1)
        i = int(np.lexsort((highs[:, 2], reach))[-1])  # furthest out, then highest
        direction = _unit(out[i])
        elsewhere = (out @ direction) < 0.5 * np.linalg.norm(out, axis=1)  # more than 60 degrees away
        across = np.abs(np.array([-direction[1], direction[0]]) @ (highs[i, :2] - lows[i, :2]))
        if across > HANDLE_WIDTH or reach[i] < reach[elsewhere].max(initial=0.0) + 0.02:
            return None
        return np.array([*out[i] + v.body_pos(name)[:2], highs[i, 2] - 0.015])

    def _rim_grasp(self, name: str) -> tuple[np.ndarray | None, np.ndarray]:
        """For wide objects: the rim side (radial xy direction) and gripper axis with most room for the fingers
        and the hand, preferring the robot side and an upright gripper; narrow objects: (None, DOWN).

        The gripper may lean within the rim's tangent plane (the fingers still straddle the rim), which moves
        the hand off an overhang such as an open drawer above the object.
        """
        box = self.view.box(name)
        if box.short <= MAX_FINGER_SPAN or self._handle(name) is not None:
            return None, DOWN
        lows, highs = self.view.obstacles(name, box.bottom + 0.005)
        best, best_score = (None, DOWN), -np.inf
        for angle in np.linspace(-np.pi, np.pi, 24, endpoint=False):
            radial = np.array([np.cos(angle), np.sin(angle)])
            tangent = np.array([-radial[1], radial[0], 0.0])
            grip, _ = self._grasp_pose(name, radial)
            # The outer finger just outside the rim, the inner finger above the object.
            fingers = [np.array([*(box.center[:2] + radial * (box.short / 2 + d)), grip[2]]) for d in (0.015, -0.06)]
            for lean in (0.0, RIM_LEAN, -RIM_LEAN):
                axis = _unit(DOWN + lean * tangent)
                points = np.array(fingers + self._hand_points(grip, axis, np.array([*radial, 0.0])))
                score = min(0.04, _box_gap(points, lows, highs)) - 0.01 * radial[0] - 0.005 * abs(lean)  # robot at -x
                if score > best_score:
                    best, best_score = (radial, axis), score
        return best

    @staticmethod
    def _hand_points(grip: np.ndarray, axis: np.ndarray, finger: np.ndarray) -> list[np.ndarray]:
        """Sample points of the hand (its 0.21 m span along the fingers, 0.05-0.13 m back from the grip point)
        and of the wrist above it, for a grasp at `grip` with approach `axis` and finger direction `finger`."""
        back = -axis
        hand = [grip + back * h + finger * f for h in (0.05, 0.13) for f in np.linspace(-0.09, 0.09, 5)]
        return hand + [grip + back * h for h in (0.2, 0.3)]

    def _pick(self, name: str, lift_z: float) -> Skill:
        for _attempt in range(3):
            start_z = self.view.box(name).bottom
            hover = max(self.view.box(name).top + 0.08, self.view.eef_pos()[2])
            radial, axis = self._rim_grasp(name)

            def above(h: float = hover, r: np.ndarray | None = radial, a: np.ndarray = axis):
                pos, yaw = self._grasp_pose(name, r)
                return pos - a * (h - pos[2]) / -a[2], yaw  # back along the approach axis, up to height h

            yield from self._move(above, OPEN, tol=0.01, max_steps=80, axis=axis)
            yield from self._move(lambda r=radial: self._grasp_pose(name, r), OPEN, tol=0.006, max_steps=50,
                                  max_speed=0.6, axis=axis)
            yield from self._hold(CLOSE, 12, axis=axis)
            eef = self.view.eef_pos()
            # Also clear the object's own support (a cabinet top) and the walls around it (a drawer's).
            up = max(lift_z, eef[2] + 0.08, eef[2] + self._walls_top(name) + 0.03 - self.view.box(name).bottom)
            yield from self._move(lambda e=eef, z=up: (np.array([e[0], e[1], z]), None), CLOSE,
                                  tol=0.02, max_steps=40)
            if self.view.box(name).bottom > start_z + 0.03:
                return
            yield from self._hold(OPEN, 8)
        raise ExpertFailure(f"could not grasp {name}")

    def _walls_top(self, name: str) -> float:
        """Top of the highest collision geom beside object `name` (overlapping its footprint widened by 2 cm and
        starting below its top), e.g. the walls of the drawer it stands in; its bottom if there is none."""
        box = self.view.box(name)
        lows, highs = self.view.obstacles(name, box.bottom)
        beside = np.all((lows[:, :2] < box.high[:2] + 0.02) & (highs[:, :2] > box.low[:2] - 0.02), axis=1)
        beside &= lows[:, 2] < box.top
        return float(highs[beside, 2].max(initial=box.bottom))

    def _free_spot(self, name: str, place: str, floor_z: float, roof_z: float = np.inf) -> tuple[np.ndarray, float]:
        """xy in region site `place` (on a fixture) where object `name` keeps most clearance from what reaches
        above `floor_z`, the top of what it will stand on (a first moka pot on the stove, the cabinet over the
        back of an open drawer), and starts below `roof_z`, nearest the centre among equals; and that clearance
        (capped at 2 cm)."""
        v = self.view
        lows, highs = v.obstacles(name, floor_z + 0.005, below_z=roof_z)
        center = v.site_pos(place)[:2]
        half = v.site_half_size(place)[:2] - 0.01
        radius = v.box(name).short / 2
        grid = center + half * np.stack(np.meshgrid(*[np.linspace(-1, 1, 41)] * 2), -1).reshape(-1, 2)
        clearance = np.minimum(0.02, _box_gaps(grid, lows[:, :2], highs[:, :2]) - radius)
        best = int(np.argmax(clearance - 0.1 * np.linalg.norm(grid - center, axis=1)))
        return grid[best], float(clearance[best])

    def _drawer_spot(self, name: str, place: str) -> tuple[np.ndarray, float]:
        """`_free_spot` of object `name` in drawer region `place`: between the drawer's walls, clear of the cabinet
        over its back."""
        return self._free_spot(name, place, self.view.site_floor(place) + 0.01)

    def _target(self, relation: str, place: str, name: str) -> Target:
        """Goal location of carried object `name` for `(relation name place)`; place is an object or a site."""
        v = self.view
        if place in v.inner.object_sites_dict and v.site_parent(place) is None:
            xy = v.site_pos(place)[:2]  # table region: put it there
            z = v.site_pos(place)[2]
            return Target(xy, z + 0.02, z + 0.01)
        if place in v.inner.object_sites_dict:
            joints = v.joints(place)  # a drawer region moves with its drawer
            owner = v.part_box(joints[0]) if joints else v.box(v.site_parent(place))
            site = v.site_pos(place)
            if relation == "in" and joints:
                return Target(self._drawer_spot(name, place)[0], owner.top + 0.03, owner.top + 0.01)
            if relation == "in":  # container region: drop from just above the rim
                return Target(site[:2], owner.top + 0.03, owner.top + 0.01)
            return Target(self._free_spot(name, place, owner.top)[0], max(site[2], owner.top) + 0.02, site[2] + 0.01)
        # LIBERO's `On`/`In` between objects compare body origins; a mug hanging tilted from its rim has its box
        # centre ~2 cm off its origin (at its bottom).
        return Target(v.body_pos(place)[:2], v.box(place).top + 0.03, v.box(place).top + 0.01, by_origin=True)

    def _place(self, name: str, relation: str, place: str) -> Skill:
        v = self.view
        eef, box = v.eef_pos(), v.box(name)
        target = self._target(relation, place, name)
        held = v.body_pos(name) if target.by_origin else box.center
        offset_xy = held[:2] - eef[:2]  # where the object hangs relative to the fingertips
        below = eef[2] - box.bottom
        carry_z = max(target.clear_z + below + 0.03, eef[2])

        def at(z: float):
            return lambda: (np.array([*(target.xy - offset_xy), z]), None)

        speed = 0.6 if box.short > MAX_FINGER_SPAN else 1.0  # held by the rim: a fast swing shakes it loose
        yield from self._move(at(carry_z), CLOSE, tol=0.02, max_steps=30, max_speed=speed)  # up
        yield from self._move(at(carry_z), CLOSE, tol=0.01, max_steps=100, max_speed=speed)
        yield from self._move(at(target.release_z + below), CLOSE, tol=0.01, max_steps=40, max_speed=0.5)
        yield from self._hold(OPEN, 10)
        up = v.eef_pos() + [0, 0, 0.08]
        yield from self._move(lambda: (up, None), OPEN, tol=0.02, max_steps=20)

    def _opening(self, place: str) -> np.ndarray | None:
        """Unit xy direction out of a roofed region site (a microwave's cavity) through its open side: of +-x and
        +-y, the one in which no geom of the region's owner stands beside the region; None without a roof."""
        v = self.view
        lows, highs = v.geom_boxes(v.site_parent(place))
        site, half = v.site_pos(place), v.site_half_size(place)
        over = np.all((lows[:, :2] < site[:2]) & (highs[:, :2] > site[:2]), axis=1)
        roof = over & (lows[:, 2] > site[2]) & (lows[:, 2] < site[2] + half[2])
        if v.joints(place) or not roof.any():
            return None
        for d in np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]]):
            ray = np.array([[*(site[:2] + d * t), site[2]] for t in np.linspace(0, 0.3, 30)])
            if _box_gap(ray, lows, highs) > 0:
                return d
        return None

    def _slide_in(self, name: str, place: str, out: np.ndarray) -> Skill:
        """Put object `name` into a roofed region (a microwave) through its open side `out`: grasp the part of
        the object reaching furthest that way (a mug's handle) from above, fingers across it and the gripper
        leaning back so the hand stays outside, under the roof's edge; carry the object in front of the opening
        just above the floor, slide it in until its origin is 2.5 cm inside the region, release, back out."""
        v = self.view
        axis, finger = _unit(np.append(-RIM_LEAN * out, -1.0)), np.array([-out[1], out[0]])
        lows, highs = v.geom_boxes(name)
        part = int(np.argmax((lows + highs)[:, :2] @ out))
        # Fingertips 1.4 cm below the part's top, relative to the object's origin (held rigidly from now on).
        grip = np.array([*(lows[part, :2] + highs[part, :2]) / 2, highs[part, 2] - 0.014]) - v.body_pos(name)
        yield from self._move(lambda: (v.body_pos(name) + grip - axis * 0.1, finger), OPEN, tol=0.01, max_steps=100,
                              axis=axis)
        yield from self._move(lambda: (v.body_pos(name) + grip, finger), OPEN, tol=0.006, max_steps=60,
                              max_speed=0.5, axis=axis)
        yield from self._hold(CLOSE, 12, finger, axis)
        site, half, floor = v.site_pos(place), v.site_half_size(place), v.site_floor(place) + 0.01
        spot = self._free_spot(name, place, floor, roof_z=floor + v.box(name).height)[0]
        depth = site[:2] @ out + half[:2] @ np.abs(out) - 0.025  # the origin's coordinate along `out`
        goal = spot + out * (depth - spot @ out)
        front = goal + 0.13 * out  # clear of the opening
        # The origin (at the object's bottom): above the front, down to just above the floor, then in.
        for xy, z, speed in ((front, floor + 0.1, 0.6), (front, floor + 0.01, 0.5), (goal, floor + 0.01, 0.4)):
            origin = np.array([*xy, z])
            yield from self._move(lambda o=origin: (o + grip, finger), CLOSE, tol=0.01, max_steps=100,
                                  max_speed=speed, axis=axis)
        yield from self._hold(OPEN, 10, finger, axis)
        back = v.eef_pos() + 0.1 * np.append(out, 0.0)
        yield from self._move(lambda: (back, finger), OPEN, tol=0.02, max_steps=30, axis=axis)

    def _path_clearance(self, name: str, radius: float, path: list[np.ndarray]) -> float:
        """Smallest xy gap between the obstacles and a disc of `radius` swept along the polyline `path`."""
        lows, highs = self.view.obstacles(name, self.view.box(name).bottom + 0.005)
        points = np.concatenate([np.linspace(a, b, 20) for a, b in zip(path[:-1], path[1:], strict=True)])
        return _box_gap(points, lows[:, :2], highs[:, :2]) - radius

    def _push_plan(self, name: str, place: str) -> list[np.ndarray]:
        """Path of the object's centre: from where it is to a point of the table region clear of obstacles,
        straight or L-shaped (axis-aligned legs), whichever keeps most clearance."""
        v = self.view
        box = v.box(name)
        radius = box.long / 2
        half = v.site_half_size(place)[:2] - 0.015  # margin inside the region
        center = v.site_pos(place)[:2]
        grid = [center + half * np.array([i, j]) for i in np.linspace(-1, 1, 5) for j in np.linspace(-1, 1, 5)]
        goal = max(grid, key=lambda p: min(0.02, self._path_clearance(name, radius, [p, p]))
                   - 0.1 * np.linalg.norm(p - center))
        start = box.center[:2]
        paths = [[start, goal], [start, np.array([start[0], goal[1]]), goal],
                 [start, np.array([goal[0], start[1]]), goal]]
        return max(paths, key=lambda p: min(0.02, self._path_clearance(name, radius, p)) - 0.01 * len(p))

    def _push(self, name: str, place: str) -> Skill:
        """Push a flat object (a plate) along the table into a table region, one straight leg at a time.

        From behind, closed fingers across the motion press its rim just above the table, the gripper leaning
        back so the hand stays above the object, clear of what stands behind it. Towards the robot (at -x),
        where the wrist cannot reach behind, open fingers across the motion stand on its floor and press the
        leading side of the rim from inside (closed fingers there tilt the object up onto them).
        """
        v = self.view
        behind = v.box(name).long / 2 + 0.012

        def from_inside(wp: np.ndarray) -> bool:
            return _unit(wp - v.box(name).center[:2])[0] <= -0.5

        def pose(wp: np.ndarray, ahead: float = 0.0, hover: float = 0.0):
            """Fingertip target, finger direction and gripper axis for the leg towards `wp`."""
            c = v.box(name).center[:2]
            u = _unit(wp - c)
            if from_inside(wp):
                xy, z, axis = c + u * (0.015 + ahead), v.box(name).bottom + 0.019, DOWN
            else:  # finger bottoms ~3 mm above the table
                xy, z = c - u * (behind - ahead), v.box(name).bottom + 0.016
                axis = _unit(np.array([-u[0] * PUSH_LEAN, -u[1] * PUSH_LEAN, -1.0]))
            return np.array([*xy, z + hover]), np.array([-u[1], u[0]]), axis

        for waypoint in self._push_plan(name, place)[1:]:
            grip = OPEN if from_inside(waypoint) else CLOSE
            axis = pose(waypoint)[2]
            above = 0.04 if from_inside(waypoint) else 0.1
            for hover, speed in ((above, 0.6), (0.0, 0.4)):  # above the leg's start, then down to it
                yield from self._move(lambda h=hover, wp=waypoint: pose(wp, hover=h)[:2], grip, tol=0.01,
                                      max_steps=80, max_speed=speed, axis=axis)
            for _ in range(120):
                dist = np.linalg.norm(waypoint - v.box(name).center[:2])
                if dist < 0.01:
                    break
                pos, finger, axis = pose(waypoint, ahead=0.05)
                slowest = 0.4 if grip == OPEN else 0.25  # from inside the rim gives less purchase: push harder
                yield self._action(pos, finger, grip, axis, max_speed=float(np.clip(3 * dist, slowest, 0.5)))
            up = v.eef_pos() + [0, 0, 0.06]
            yield from self._move(lambda p=up: (p, None), grip, tol=0.02, max_steps=20)

    # Articulated fixtures ------------------------------------------------------------------------------
    def _joint(self, name: str) -> str:
        joints = self.view.joints(name)
        if len(joints) != 1:
            raise ExpertFailure(f"{name} has joints {joints}; the expert drives exactly one")
        return joints[0]

    def _pull_drawer_open(self, name: str, joint: str, outward: np.ndarray) -> Skill:
        """Open a drawer: grasp its handle from the front, gripper level, pull until it is open."""
        v = self.view
        axis, finger = -outward, np.array([0.0, 0.0, 1.0])  # point into the front, fingers above and below
        start, start_finger = v.eef_pos(), v.finger_axis()
        yield from self._move(lambda: (start, finger), OPEN, tol=0.05, max_steps=40, axis=axis)  # turn in place
        front = v.handle_pos(joint, outward) + 0.12 * outward
        above = [*front[:2], max(start[2], front[2] + 0.1)]  # come down in front of the handle, over the table
        yield from self._move(lambda: (above, finger), OPEN, tol=0.03, max_steps=60, axis=axis)
        yield from self._move(lambda: (front, finger), OPEN, tol=0.02, max_steps=60, axis=axis)
        yield from self._move(lambda: (v.handle_pos(joint, outward) - 0.005 * outward, finger), OPEN, tol=0.008,
                              max_steps=50, max_speed=0.5, axis=axis)
        yield from self._hold(CLOSE, 12, finger, axis)
        for _ in range(120):
            if v.holds("open", name):
                break
            yield self._action(v.handle_pos(joint, outward) + 0.04 * outward, finger, CLOSE, axis, max_speed=0.6)
        yield from self._hold(OPEN, 8, finger, axis)
        back = v.eef_pos() + 0.1 * outward
        yield from self._move(lambda: (back, finger), OPEN, tol=0.02, max_steps=30, axis=axis)
        # Turn back the way it came, so the wrist keeps its range for the next skill.
        yield from self._move(lambda: (back + [0, 0, 0.05], start_finger), OPEN, tol=0.03, max_steps=40)

    def _push_drawer_shut(self, name: str, joint: str, outward: np.ndarray) -> Skill:
        """Close a drawer by pushing its handle in: closed fingers across the motion, the gripper leaning forward
        so the hand trails the fingertips, clear of the cabinet front above the drawer."""
        v = self.view
        axis = _unit(DOWN - PUSH_LEAN * outward)
        finger = np.array([-outward[1], outward[0]])

        def at(out: float, hover: float = 0.0):
            return v.handle_pos(joint, outward) + out * outward + [0, 0, hover], finger

        yield from self._move(lambda: at(0.04, 0.1), CLOSE, tol=0.02, max_steps=80, axis=axis)
        yield from self._move(lambda: at(0.025), CLOSE, tol=0.01, max_steps=60, max_speed=0.5, axis=axis)
        for _ in range(120):
            if v.holds("close", name):
                break
            yield self._action(*at(-0.04), CLOSE, axis, max_speed=0.5)
        back = v.eef_pos() + 0.08 * outward + [0, 0, 0.05]
        yield from self._move(lambda: (back, None), CLOSE, tol=0.02, max_steps=30)

    def _push_drawer_to_stop(self, name: str) -> Skill:
        """Push an open drawer out to its stop from inside: closed fingers across the motion press the inner face
        of its front, so that a wide object (a bowl) fits between the front and the cabinet over the back."""
        v, joint = self.view, self._joint(name)
        sign = self._open_sign(name)
        outward, stop = v.joint_axis(joint) * sign, v.joint_range(joint)[int(sign > 0)]
        finger = np.array([-outward[1], outward[0]])

        def at(out: float, hover: float = 0.0):
            """A point `out` from the front's inner face (the region site's side), 2 cm above the floor."""
            site, half = v.site_pos(name), v.site_half_size(name)
            point = site + outward * (half @ np.abs(outward) - 0.015 + out)
            return np.array([point[0], point[1], v.site_floor(name) + 0.02 + hover]), finger

        yield from self._move(lambda: at(0.0, 0.1), CLOSE, tol=0.02, max_steps=80)
        yield from self._move(lambda: at(0.0), CLOSE, tol=0.01, max_steps=60, max_speed=0.5)
        for _ in range(60):
            if abs(v.joint_qpos(joint) - stop) < 0.003:
                break
            yield self._action(*at(0.04), CLOSE, max_speed=0.5)
        up = v.eef_pos() + [0, 0, 0.1]
        yield from self._move(lambda: (up, None), CLOSE, tol=0.02, max_steps=30)

    def _turn_knob(self, name: str, joint: str, predicate: str, sign: float) -> Skill:
        """Turn a knob (a hinge about the vertical): grasp its top ridge from above and twist until it is on."""
        v = self.view
        ridge = v.top_part_box(joint)
        grasp = np.array([*v.joint_anchor(joint)[:2], ridge.top - 0.012])
        yield from self._move(lambda: (grasp + [0, 0, 0.08], ridge.short_dir), OPEN, tol=0.01, max_steps=80)
        yield from self._move(lambda: (grasp, ridge.short_dir), OPEN, tol=0.006, max_steps=40, max_speed=0.5)
        yield from self._hold(CLOSE, 10, ridge.short_dir)
        f0, q0 = v.finger_axis(), v.joint_qpos(joint)
        rot_axis = v.joint_axis(joint) * sign
        for _ in range(60):
            if v.holds(predicate, name):
                break
            angle = abs(v.joint_qpos(joint) - q0) + 0.4  # keep the twist a little ahead of the knob
            yield self._action(grasp, _rotation(rot_axis, angle) @ f0, CLOSE)
        yield from self._hold(OPEN, 8)
        yield from self._move(lambda: (grasp + [0, 0, 0.1], None), OPEN, tol=0.02, max_steps=30)

    def _swing_door(self, name: str, joint: str, predicate: str, sign: float) -> Skill:
        """Swing a door about its vertical hinge: closed fingers press the face that trails the motion, near
        the free edge at mid height, and follow the arc until LIBERO's predicate holds."""
        v = self.view
        axis = v.joint_axis(joint) * sign

        def contact(ahead: float, hover: float = 0.0):
            """A point of the door 3/4 of the way to its free edge, `ahead` along its motion there."""
            anchor, pts = v.joint_anchor(joint), v.part_corners(joint)
            arms = pts - anchor
            arms -= np.outer(arms @ axis, axis)  # horizontal lever arms about the hinge
            radial = arms[int(np.argmax(np.linalg.norm(arms, axis=1)))]  # to the free edge
            tangent = _unit(np.cross(axis, radial))
            mid_z = (pts[:, 2].min() + pts[:, 2].max()) / 2
            point = anchor + 0.75 * radial + tangent * ahead
            return np.array([point[0], point[1], mid_z + hover]), _unit(radial[:2])

        yield from self._move(lambda: contact(-0.04, 0.25), CLOSE, tol=0.02, max_steps=80)
        yield from self._move(lambda: contact(-0.04), CLOSE, tol=0.015, max_steps=60, max_speed=0.6)
        for _ in range(150):
            if v.holds(predicate, name):
                break
            yield self._action(*contact(0.03), CLOSE, max_speed=0.5)
        back = v.eef_pos() + [0, 0, 0.1]
        yield from self._move(lambda: (back, None), CLOSE, tol=0.02, max_steps=20)

    def _open_sign(self, name: str) -> float:
        """+1 if the drawer behind region `name` opens towards larger qpos, else -1."""
        art = self.view.articulation(name)
        return float(np.sign(np.mean(art["default_open_ranges"]) - np.mean(art["default_close_ranges"])))

    def _articulate(self, name: str, predicate: str) -> Skill:
        """Bring the fixture part behind `name` (a drawer region, a stove) to satisfy `predicate`."""
        v, joint = self.view, self._joint(name)
        art = v.articulation(name)
        if v.joint_is_slide(joint) and predicate in ("open", "close"):
            outward = v.joint_axis(joint) * self._open_sign(name)  # a drawer's front faces the way it opens
            if predicate == "open":
                yield from self._pull_drawer_open(name, joint, outward)
            else:
                yield from self._push_drawer_shut(name, joint, outward)
        elif not v.joint_is_slide(joint) and predicate == "turnon" and abs(v.joint_axis(joint)[2]) > 0.9:
            sign = np.sign(np.mean(art["default_turnon_ranges"]) - v.joint_qpos(joint))
            yield from self._turn_knob(name, joint, predicate, sign)
        elif not v.joint_is_slide(joint) and predicate in ("open", "close") and abs(v.joint_axis(joint)[2]) > 0.9:
            ranges = art[f"default_{predicate}_ranges"]
            yield from self._swing_door(name, joint, predicate, np.sign(np.mean(ranges) - v.joint_qpos(joint)))
        else:
            raise ExpertFailure(f"no skill for ({predicate} {name}) with joint {joint}")

    def _run(self) -> Skill:
        for predicate, *args in sorted(self.goal, key=lambda p: SKILL_ORDER[p[0]]):
            if predicate in ("in", "on"):
                obj, place = args
                box = self.view.box(obj)
                table_region = place in self.view.inner.object_sites_dict and self.view.site_parent(place) is None
                if predicate == "on" and table_region and box.short > MAX_FINGER_SPAN and box.height < MIN_GRASP_HEIGHT:
                    yield from self._push(obj, place)
                    continue
                out = self._opening(place) if predicate == "in" and place in self.view.inner.object_sites_dict else None
                if out is not None:
                    yield from self._slide_in(obj, place, out)
                    continue
                if predicate == "in" and self.view.joints(place):
                    if not self.view.holds("open", place):
                        yield from self._articulate(place, "open")
                    if self._drawer_spot(obj, place)[1] < 0.005:  # too tight to lower it in
                        yield from self._push_drawer_to_stop(place)
                target = self._target(predicate, place, obj)
                lift_z = target.clear_z + self.view.box(obj).height + 0.08
                yield from self._pick(obj, lift_z)
                yield from self._place(obj, predicate, place)
            elif not self.view.holds(predicate, args[0]):
                yield from self._articulate(args[0], predicate)

    # Public API ------------------------------------------------------------------------------------
    def act(self) -> np.ndarray:
        """Next action; after the plan ends, holds still with the gripper open (`done` becomes True)."""
        try:
            return next(self._plan)
        except StopIteration:
            self.done = True
            return np.array([0, 0, 0, 0, 0, 0, OPEN], dtype=float)
