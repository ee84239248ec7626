"""Grasps: top-down across an object's narrow side, by the rim of wide objects, by a handle; pick and lift."""

import numpy as np

from lerobot_predvla.sims.libero.expert.motion import (
    CLOSE,
    DOWN,
    HANDLE_WIDTH,
    MAX_FINGER_SPAN,
    OPEN,
    RIM_LEAN,
    ExpertFailure,
    Motion,
    Skill,
    _box_gap,
    _unit,
)


class Grasping(Motion):
    """Grasp skills: choose the grasp pose and the finger direction, pick up and lift."""

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

            yield from self._move(above, OPEN, tol=0.01, max_steps=80, axis=axis, phase="approach")
            yield from self._move(lambda r=radial: self._grasp_pose(name, r), OPEN, tol=0.006, max_steps=50,
                                  max_speed=0.6, axis=axis, phase="descend")
            yield from self._hold(CLOSE, 12, axis=axis, phase="close")
            eef = self.view.eef_pos()
            # Also clear the object's own support (a cabinet top) and the walls around it (a drawer's).
            up = max(lift_z, eef[2] + 0.08, eef[2] + self._walls_top(name) + 0.03 - self.view.box(name).bottom)
            yield from self._move(lambda e=eef, z=up: (np.array([e[0], e[1], z]), None), CLOSE,
                                  tol=0.02, max_steps=40, phase="lift")
            if self.view.box(name).bottom > start_z + 0.03:
                return
            yield from self._hold(OPEN, 8)
        raise ExpertFailure(f"could not grasp {name}")
