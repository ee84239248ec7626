"""Privileged geometry read from a LIBERO simulation: gripper pose, object bounding boxes, region sites."""

from dataclasses import dataclass

import numpy as np

GRIP_SITE = "gripper0_grip_site"
FINGER_BODIES = ("gripper0_leftfinger", "gripper0_rightfinger")


@dataclass
class Box:
    """An object's collision geometry: world AABB plus its horizontal extents in its own frame."""

    center: np.ndarray  # world AABB centre (3,)
    low: np.ndarray  # world AABB min corner (3,)
    high: np.ndarray  # world AABB max corner (3,)
    short_dir: np.ndarray  # unit xy direction of the narrower horizontal side
    short: float  # horizontal extent along short_dir
    long: float  # horizontal extent across it

    @property
    def bottom(self) -> float:
        return float(self.low[2])

    @property
    def top(self) -> float:
        return float(self.high[2])

    @property
    def height(self) -> float:
        return float(self.high[2] - self.low[2])


class SceneView:
    """Reads poses from the MuJoCo state of a LIBERO env (robosuite's MjSim wrapper)."""

    def __init__(self, env) -> None:
        self.inner = env.env
        self.sim = env.sim
        self.model = self.sim.model._model
        self._geoms: dict[str, np.ndarray] = {}

    # Gripper -----------------------------------------------------------------------------------
    def eef_pos(self) -> np.ndarray:
        return self.sim.data.site_xpos[self.sim.model.site_name2id(GRIP_SITE)].copy()

    def eef_axis_z(self) -> np.ndarray:
        return self.sim.data.site_xmat[self.sim.model.site_name2id(GRIP_SITE)].reshape(3, 3)[:, 2].copy()

    def finger_axis(self) -> np.ndarray:
        """Unit 3D direction along which the two fingers close."""
        left, right = (self.sim.data.body_xpos[self.sim.model.body_name2id(b)] for b in FINGER_BODIES)
        d = left - right
        return d / (np.linalg.norm(d) + 1e-9)

    def gripper_width(self) -> float:
        qpos = self.sim.data.qpos[self.inner.robots[0]._ref_gripper_joint_pos_indexes]
        return float(qpos[0] - qpos[1])

    # Objects -------------------------------------------------------------------------------------
    def _body_id(self, name: str) -> int:
        obj = self.inner.get_object(name)
        if obj is None:
            raise KeyError(f"no object or fixture {name!r} in this LIBERO task")
        return self.sim.model.body_name2id(obj.root_body)

    def _subtree_geoms(self, root: int) -> np.ndarray:
        """Collision geoms of body `root` and its descendants."""
        m = self.model
        bodies = {root}
        for b in range(m.nbody):  # bodies are ordered parents first
            if m.body_parentid[b] in bodies:
                bodies.add(b)
        return np.array([g for g in range(m.ngeom)
                         if m.geom_bodyid[g] in bodies and (m.geom_contype[g] or m.geom_conaffinity[g])])

    def _collision_geoms(self, name: str) -> np.ndarray:
        if name not in self._geoms:
            self._geoms[name] = self._subtree_geoms(self._body_id(name))
        return self._geoms[name]

    def body_pos(self, name: str) -> np.ndarray:
        return self.sim.data.body_xpos[self._body_id(name)].copy()

    def _corners(self, geoms: np.ndarray) -> np.ndarray:
        """World corners of each geom's local AABB, (8 * len(geoms), 3)."""
        m, d = self.model, self.sim.data._data
        signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
        return np.concatenate([d.geom_xpos[g] + (m.geom_aabb[g, :3] + signs * m.geom_aabb[g, 3:])
                               @ d.geom_xmat[g].reshape(3, 3).T for g in geoms])

    def box(self, name: str) -> Box:
        """Bounding box of an object's collision geoms (corners of each geom's local AABB)."""
        return self._box(self._corners(self._collision_geoms(name)),
                         self.sim.data._data.xmat[self._body_id(name)].reshape(3, 3))

    @staticmethod
    def _box(pts: np.ndarray, rot: np.ndarray) -> Box:
        """Box around points `pts`; horizontal extents along the axes of frame `rot`."""
        low, high = pts.min(0), pts.max(0)
        # Horizontal extents in the object's own frame: drop its most vertical axis.
        axes = [rot[:, i] for i in np.argsort(np.abs(rot[2, :]))[:2]]
        extents = [float(np.ptp(pts @ a)) for a in axes]
        i_short = int(np.argmin(extents))
        short_dir = axes[i_short][:2] / (np.linalg.norm(axes[i_short][:2]) + 1e-9)
        return Box((low + high) / 2, low, high, short_dir, extents[i_short], extents[1 - i_short])

    def geom_boxes(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """World AABBs (lows, highs), one per collision geom of object `name`."""
        geoms = self._collision_geoms(name)
        pts = self._corners(geoms).reshape(len(geoms), 8, 3)
        return pts.min(1), pts.max(1)

    def obstacles(self, name: str, above_z: float, below_z: float = np.inf) -> tuple[np.ndarray, np.ndarray]:
        """World AABBs (lows, highs) of the scene's collision geoms reaching above `above_z` (and starting below
        `below_z`), except the robot's and those of object `name`."""
        m = self.model
        own = set(self._collision_geoms(name).tolist())
        robot = {b for b in range(m.nbody) if self.sim.model.body_id2name(b).startswith(("robot", "gripper"))}
        geoms = [g for g in range(m.ngeom) if (m.geom_contype[g] or m.geom_conaffinity[g])
                 and g not in own and m.geom_bodyid[g] not in robot]
        pts = self._corners(np.array(geoms)).reshape(len(geoms), 8, 3)
        lows, highs = pts.min(1), pts.max(1)
        keep = (highs[:, 2] > above_z) & (lows[:, 2] < below_z)
        return lows[keep], highs[keep]

    # Articulations --------------------------------------------------------------------------------
    def joints(self, name: str) -> list[str]:
        """Joints behind a goal predicate on `name`: a fixture, or a fixture's region site (a drawer)."""
        site = self.inner.object_sites_dict.get(name)
        if site is not None:
            return list(getattr(site, "joints", None) or [])
        return list(getattr(self.inner.get_object(name), "joints", None) or [])

    def articulation(self, name: str) -> dict:
        """The fixture's LIBERO articulation ranges (`default_open_ranges`, `default_turnon_ranges`, ...)."""
        owner = self.site_parent(name) or name
        return self.inner.get_object(owner).object_properties["articulation"]

    def joint_qpos(self, joint: str) -> float:
        return float(self.sim.data.qpos[self.sim.model.get_joint_qpos_addr(joint)])

    def joint_is_slide(self, joint: str) -> bool:
        return bool(self.model.jnt_type[self.sim.model.joint_name2id(joint)] == 2)  # mjJNT_SLIDE

    def joint_range(self, joint: str) -> np.ndarray:
        """The joint's limits (lower, upper) in qpos units."""
        return self.model.jnt_range[self.sim.model.joint_name2id(joint)].copy()

    def joint_axis(self, joint: str) -> np.ndarray:
        """World direction of the joint axis (motion per unit qpos for slides, rotation axis for hinges)."""
        return self.sim.data._data.xaxis[self.sim.model.joint_name2id(joint)].copy()

    def joint_anchor(self, joint: str) -> np.ndarray:
        return self.sim.data._data.xanchor[self.sim.model.joint_name2id(joint)].copy()

    def part_geoms(self, joint: str) -> np.ndarray:
        """Collision geoms moved by `joint` (the drawer, door or knob it carries)."""
        return self._subtree_geoms(int(self.model.jnt_bodyid[self.sim.model.joint_name2id(joint)]))

    def part_corners(self, joint: str) -> np.ndarray:
        """World corners of the collision geoms moved by `joint`, (8 * n, 3)."""
        return self._corners(self.part_geoms(joint))

    def handle_pos(self, joint: str, outward: np.ndarray) -> np.ndarray:
        """Centre of the moving part's collision geom that sticks out furthest along `outward` (its handle)."""
        centers = self.sim.data._data.geom_xpos[self.part_geoms(joint)]
        return centers[int(np.argmax(centers @ outward))].copy()

    def part_box(self, joint: str) -> Box:
        """Box of the part moved by `joint` (a drawer), in the part's frame."""
        body = int(self.model.jnt_bodyid[self.sim.model.joint_name2id(joint)])
        return self._box(self.part_corners(joint), self.sim.data._data.xmat[body].reshape(3, 3))

    def holds(self, predicate: str, name: str) -> bool:
        """LIBERO's own test of a unary goal predicate (`open`, `close`, `turnon`) on a fixture or region."""
        method = {"open": "is_open", "close": "is_close", "turnon": "turn_on"}[predicate]
        return bool(getattr(self.inner.object_states_dict[name], method)())

    def top_part_box(self, joint: str) -> Box:
        """Box of the moving part's highest collision geom (a knob's grip ridge), in that geom's frame."""
        d = self.sim.data._data
        geoms = self.part_geoms(joint)
        tops = [self._corners(np.array([g]))[:, 2].max() for g in geoms]
        g = geoms[int(np.argmax(tops))]
        return self._box(self._corners(np.array([g])), d.geom_xmat[g].reshape(3, 3))

    # Regions ---------------------------------------------------------------------------------------
    def site_pos(self, name: str) -> np.ndarray:
        return self.sim.data.site_xpos[self.sim.model.site_name2id(name)].copy()

    def site_half_size(self, name: str) -> np.ndarray:
        """World half extents (3,) of region site `name`, as LIBERO's containment test takes them."""
        size = np.asarray(self.inner.object_sites_dict[name].size)
        return np.abs(self.sim.data.site_xmat[self.sim.model.site_name2id(name)].reshape(3, 3) @ size)

    def site_floor(self, name: str) -> float:
        """Height of the bottom face of region site `name` (a drawer's or a cavity's floor)."""
        return float(self.site_pos(name)[2] - self.site_half_size(name)[2])

    def site_parent(self, name: str) -> str | None:
        site = self.inner.object_sites_dict.get(name)
        return getattr(site, "parent_name", None)
