"""Placing a held object: on or in a target, in a drawer, slid into an opening such as a microwave's."""

from dataclasses import dataclass

import numpy as np

from lerobot_predvla.sims.libero.expert.grasp import Grasping
from lerobot_predvla.sims.libero.expert.motion import (
    CLOSE,
    MAX_FINGER_SPAN,
    OPEN,
    RIM_LEAN,
    Skill,
    _box_gap,
    _box_gaps,
    _unit,
)


@dataclass
class Target:
    """Where a carried object goes: xy of its centre (of its body origin if `by_origin`), height to clear,
    height of its bottom at release."""

    xy: np.ndarray
    clear_z: float
    release_z: float
    by_origin: bool = False


class Placing(Grasping):
    """Place skills: carry a held object to its target and release it."""

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
        yield from self._move(at(carry_z), CLOSE, tol=0.02, max_steps=30, max_speed=speed, phase="carry")  # up
        yield from self._move(at(carry_z), CLOSE, tol=0.01, max_steps=100, max_speed=speed)
        yield from self._move(at(target.release_z + below), CLOSE, tol=0.01, max_steps=40, max_speed=0.5, phase="lower")
        yield from self._hold(OPEN, 10, phase="release")
        up = v.eef_pos() + [0, 0, 0.08]
        yield from self._move(lambda: (up, None), OPEN, tol=0.02, max_steps=20, phase="retreat")

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
