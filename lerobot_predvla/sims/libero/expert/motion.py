"""Motion primitives of the scripted expert: proportional moves of the default OSC_POSE controller.

Each skill is a generator that yields 7-dim delta actions (xyz, axis-angle, gripper); motions are proportional
moves towards waypoints computed from current object poses.
"""

from collections.abc import Iterator

import numpy as np

from lerobot_predvla.sims.libero.geometry import SceneView

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
# How the expert picks between a finger direction and its half turn (`predvla demos --half-turn`):
# "nearest": the one nearer the current finger direction (every recorded dataset so far). Near a tie, as on three
#   libero_object tasks when the arm's start carries the official init states' joint noise, the start noise
#   decides, and demonstrations of one task end on wrist angles half a turn apart (docs/research/arm_start_pose.md).
# "wrist_centre": the one that leaves the wrist joint nearer the middle of its range; ties are far from the start.
HALF_TURN_RULES = ("nearest", "wrist_centre")
DEFAULT_HALF_TURN = "nearest"  # every recorded dataset; "wrist_centre" fails two libero_goal tasks (docs/libero.md)

Skill = Iterator[np.ndarray]


class ExpertFailure(RuntimeError):
    """The expert gave up (no plan for a predicate, or repeated grasp failure)."""


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


class Motion:
    """Low-level control shared by every skill; `view` (a SceneView), `speed` and `half_turn` are set by
    ScriptedExpert."""

    view: SceneView
    speed: float
    half_turn: str

    def _finger_goal(self, axis: np.ndarray, finger: np.ndarray | None) -> np.ndarray:
        """Goal finger direction: `finger` (xy or 3D) made normal to `axis`; None keeps the current finger
        direction. A parallel gripper is symmetric under a half turn, so `finger` and `-finger` grasp alike:
        `half_turn` picks one (HALF_TURN_RULES)."""
        f_now = _tilt(self.view.eef_axis_z(), axis) @ self.view.finger_axis()
        f = f_now if finger is None else np.pad(finger, (0, 3 - len(finger)))
        f = _unit(f - (f @ axis) * axis)
        if self.half_turn == "nearest":
            return f if f @ f_now >= 0 else -f
        joint = self.view.inner.robots[0].robot_joints[-1]  # the wrist: turns the fingers about the approach axis
        q, wrist_axis = self.view.joint_qpos(joint), self.view.joint_axis(joint)
        mid = float(self.view.joint_range(joint).mean())

        def wrist_after(g: np.ndarray) -> float:  # the wrist angle once the fingers are turned from f_now onto g
            return q + float(np.arctan2(np.cross(f_now, g) @ wrist_axis, f_now @ g))

        return f if abs(wrist_after(f) - mid) <= abs(wrist_after(-f) - mid) else -f

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
              axis: np.ndarray = DOWN, phase: str = "") -> Skill:
        """Move until within `tol` of goal() -> (pos, finger); goal is re-evaluated every step. `phase` names what
        the move is for in a pick and place ("approach", "descend", "lift", "carry", "lower", "retreat"): the
        script moves alike whatever it is, the teleoperator model (teleop.py) perturbs by it."""
        for _ in range(max_steps):
            pos, finger = goal()
            if np.linalg.norm(pos - self.view.eef_pos()) < tol and (
                    finger is None or np.linalg.norm(self._rot_error(axis, finger)) < 0.08):
                return
            yield self._action(pos, finger, grip, axis, max_speed=max_speed)

    def _hold(self, grip: float, steps: int, finger: np.ndarray | None = None, axis: np.ndarray = DOWN,
              phase: str = "") -> Skill:
        """Hold the hand where it is for `steps` steps with the gripper at `grip`; `phase` ("close", "release") as in
        `_move`."""
        pos = self.view.eef_pos()
        for _ in range(steps):
            yield self._action(pos, finger, grip, axis)
