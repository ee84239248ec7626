"""Pushing a wide flat object (a plate) along the table on a straight or L-shaped path."""

import numpy as np

from lerobot_predvla.sims.libero.expert.motion import CLOSE, DOWN, OPEN, PUSH_LEAN, Motion, Skill, _box_gap, _unit


class Pushing(Motion):
    """Push skills: slide a flat object along the table around what stands in the way."""

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
