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
SUPPORTED_PREDICATES = ("in", "on")

Skill = Iterator[np.ndarray]


class ExpertFailure(RuntimeError):
    """The expert gave up (no plan for a predicate, or repeated grasp failure)."""


@dataclass
class Target:
    """Where a carried object goes: xy of its centre, height to clear, height of its bottom at release."""

    xy: np.ndarray
    clear_z: float
    release_z: float


def _wrap_half_pi(angle: float) -> float:
    """Wrap to (-pi/2, pi/2]: a parallel gripper is symmetric under a half turn."""
    return float((angle + np.pi / 2) % np.pi - np.pi / 2)


class ScriptedExpert:
    """Solves LIBERO `In`/`On` goals by pick-and-place; call `act()` once per control step."""

    def __init__(self, env, speed: float = 1.0, rng: np.random.Generator | None = None) -> None:
        self.view = SceneView(env)
        self.goal = [tuple(p) for p in env.env.parsed_problem["goal_state"]]
        unsupported = [p for p in self.goal if p[0] not in SUPPORTED_PREDICATES]
        if unsupported:
            raise ExpertFailure(f"no scripted plan for goal predicates {unsupported}")
        self.speed = speed
        self.rng = rng or np.random.default_rng()
        self._plan = self._run()
        self.done = False

    # Low-level control ---------------------------------------------------------------------------
    def _action(self, pos: np.ndarray, yaw_dir: np.ndarray | None, grip: float, gain: float = 1.0,
                max_speed: float = 1.0) -> np.ndarray:
        """Proportional step towards `pos`, gripper pointing down, fingers along `yaw_dir` (xy)."""
        v = self.view
        dpos = np.clip((pos - v.eef_pos()) / POS_SCALE * 2.0 * gain, -max_speed, max_speed) * self.speed
        # Tilt: rotate the gripper axis onto -z; yaw: turn the finger axis onto yaw_dir.
        rot = np.cross(v.eef_axis_z(), [0.0, 0.0, -1.0])
        if yaw_dir is not None:
            f = v.finger_dir()
            rot[2] += _wrap_half_pi(np.arctan2(yaw_dir[1], yaw_dir[0]) - np.arctan2(f[1], f[0]))
        drot = np.clip(rot * 2.0 / ROT_SCALE, -1, 1)
        return np.concatenate([dpos, drot, [grip]])

    def _yaw_error(self, yaw_dir: np.ndarray | None) -> float:
        if yaw_dir is None:
            return 0.0
        f = self.view.finger_dir()
        return abs(_wrap_half_pi(np.arctan2(yaw_dir[1], yaw_dir[0]) - np.arctan2(f[1], f[0])))

    def _move(self, goal, grip: float, tol: float = 0.01, max_steps: int = 60,
              max_speed: float = 1.0) -> Skill:
        """Move until within `tol` of goal() -> (pos, yaw_dir); goal is re-evaluated every step."""
        for _ in range(max_steps):
            pos, yaw_dir = goal()
            if np.linalg.norm(pos - self.view.eef_pos()) < tol and self._yaw_error(yaw_dir) < 0.08:
                return
            yield self._action(pos, yaw_dir, grip, max_speed=max_speed)

    def _hold(self, grip: float, steps: int, yaw_dir: np.ndarray | None = None) -> Skill:
        pos = self.view.eef_pos()
        for _ in range(steps):
            yield self._action(pos, yaw_dir, grip)

    # Skills ----------------------------------------------------------------------------------------
    def _grasp_pose(self, name: str, radial: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        """Fingertip target and finger direction for a top-down grasp of object `name`.

        With a `radial` direction (objects wider than the fingers' span, e.g. bowls) the grasp is at
        the rim point along it; the choice is made once per attempt by `_rim_direction`.
        """
        box = self.view.box(name)
        if radial is None:
            # Narrow side between the fingers; round objects keep the current yaw.
            yaw = box.short_dir if box.long - box.short > 0.01 else None
            z = max(box.bottom + box.height / 2, box.top - 0.035)
            return np.array([box.center[0], box.center[1], z]), yaw
        xy = box.center[:2] + radial * (box.short / 2 - 0.012)
        return np.array([xy[0], xy[1], box.top - 0.02]), radial

    def _rim_direction(self, name: str) -> np.ndarray | None:
        """For wide objects: the rim side with most room for the outer finger, preferring the robot side."""
        v = self.view
        box = v.box(name)
        if box.short <= MAX_FINGER_SPAN:
            return None
        others = []
        for other in [*v.inner.objects_dict, *v.inner.fixtures_dict]:
            if other == name:
                continue
            ob = v.box(other)
            supports = np.all(ob.low[:2] <= box.center[:2]) and np.all(box.center[:2] <= ob.high[:2])
            if not supports and ob.top > box.bottom + 0.005:
                others.append(ob)
        best, best_score = None, -np.inf
        for angle in np.linspace(-np.pi, np.pi, 24, endpoint=False):
            radial = np.array([np.cos(angle), np.sin(angle)])
            finger = box.center[:2] + radial * (box.short / 2 + 0.015)
            gaps = [np.linalg.norm(np.maximum(0, np.maximum(ob.low[:2] - finger, finger - ob.high[:2])))
                    for ob in others]
            score = min([0.04, *gaps]) - 0.01 * radial[0]  # the robot stands at -x
            if score > best_score:
                best, best_score = radial, score
        return best

    def _pick(self, name: str, lift_z: float) -> Skill:
        for _attempt in range(3):
            start_z = self.view.box(name).bottom
            hover = max(self.view.box(name).top + 0.08, self.view.eef_pos()[2])
            radial = self._rim_direction(name)

            def above(h: float = hover, r: np.ndarray | None = radial):
                pos, yaw = self._grasp_pose(name, r)
                return np.array([pos[0], pos[1], h]), yaw

            yield from self._move(above, OPEN, tol=0.01, max_steps=80)
            yield from self._move(lambda r=radial: self._grasp_pose(name, r), OPEN, tol=0.006, max_steps=50,
                                  max_speed=0.6)
            yield from self._hold(CLOSE, 12)
            eef = self.view.eef_pos()
            yield from self._move(lambda e=eef: (np.array([e[0], e[1], lift_z]), None), CLOSE,
                                  tol=0.02, max_steps=40)
            if self.view.box(name).bottom > start_z + 0.03:
                return
            yield from self._hold(OPEN, 8)
        raise ExpertFailure(f"could not grasp {name}")

    def _target(self, relation: str, place: str) -> Target:
        """Goal location of a carried object for `(relation obj place)`; place is an object or a site."""
        v = self.view
        if place in v.inner.object_sites_dict and v.site_parent(place) is None:
            xy = v.site_pos(place)[:2]  # table region: put it there
            z = v.site_pos(place)[2]
            return Target(xy, z + 0.02, z + 0.01)
        if place in v.inner.object_sites_dict:
            owner = v.box(v.site_parent(place))
            site = v.site_pos(place)
            if relation == "in":  # container region: drop from just above the rim
                return Target(site[:2], owner.top + 0.03, owner.top + 0.01)
            return Target(site[:2], max(site[2], owner.top) + 0.02, site[2] + 0.01)
        box = v.box(place)
        return Target(box.center[:2], box.top + 0.03, box.top + 0.01)

    def _place(self, name: str, relation: str, place: str) -> Skill:
        v = self.view
        eef, box = v.eef_pos(), v.box(name)
        offset_xy = box.center[:2] - eef[:2]  # where the object hangs relative to the fingertips
        below = eef[2] - box.bottom
        target = self._target(relation, place)
        carry_z = max(target.clear_z + below + 0.03, eef[2])

        def at(z: float):
            return lambda: (np.array([*(target.xy - offset_xy), z]), None)

        yield from self._move(at(carry_z), CLOSE, tol=0.02, max_steps=30)  # up
        yield from self._move(at(carry_z), CLOSE, tol=0.01, max_steps=100)
        yield from self._move(at(target.release_z + below), CLOSE, tol=0.01, max_steps=40, max_speed=0.5)
        yield from self._hold(OPEN, 10)
        up = v.eef_pos() + [0, 0, 0.08]
        yield from self._move(lambda: (up, None), OPEN, tol=0.02, max_steps=20)

    def _run(self) -> Skill:
        for relation, obj, place in self.goal:
            target = self._target(relation, place)
            lift_z = target.clear_z + self.view.box(obj).height + 0.08
            yield from self._pick(obj, lift_z)
            yield from self._place(obj, relation, place)

    # Public API ------------------------------------------------------------------------------------
    def act(self) -> np.ndarray:
        """Next action; after the plan ends, holds still with the gripper open (`done` becomes True)."""
        try:
            return next(self._plan)
        except StopIteration:
            self.done = True
            return np.array([0, 0, 0, 0, 0, 0, OPEN], dtype=float)
