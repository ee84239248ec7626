"""Articulated fixtures: drawers pulled open and pushed shut, stove knobs turned, hinged doors swung."""

import numpy as np

from lerobot_predvla.sims.libero.expert.motion import (
    CLOSE,
    DOWN,
    OPEN,
    PUSH_LEAN,
    ExpertFailure,
    Motion,
    Skill,
    _rotation,
    _unit,
)


class Articulating(Motion):
    """Articulation skills: open and close drawers and doors, turn knobs."""

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
