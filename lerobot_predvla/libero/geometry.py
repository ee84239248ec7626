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

    def finger_dir(self) -> np.ndarray:
        """Unit xy direction along which the two fingers close."""
        left, right = (self.sim.data.body_xpos[self.sim.model.body_name2id(b)] for b in FINGER_BODIES)
        d = (left - right)[:2]
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

    def _collision_geoms(self, name: str) -> np.ndarray:
        if name not in self._geoms:
            m, root = self.model, self._body_id(name)
            bodies = {root}
            for b in range(m.nbody):  # bodies are ordered parents first
                if m.body_parentid[b] in bodies:
                    bodies.add(b)
            self._geoms[name] = np.array([
                g for g in range(m.ngeom)
                if m.geom_bodyid[g] in bodies and (m.geom_contype[g] or m.geom_conaffinity[g])
            ])
        return self._geoms[name]

    def body_pos(self, name: str) -> np.ndarray:
        return self.sim.data.body_xpos[self._body_id(name)].copy()

    def box(self, name: str) -> Box:
        """Bounding box of an object's collision geoms (corners of each geom's local AABB)."""
        m, d = self.model, self.sim.data._data
        signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
        corners = []
        for g in self._collision_geoms(name):
            local = m.geom_aabb[g, :3] + signs * m.geom_aabb[g, 3:]
            corners.append(d.geom_xpos[g] + local @ d.geom_xmat[g].reshape(3, 3).T)
        pts = np.concatenate(corners)
        low, high = pts.min(0), pts.max(0)
        # Horizontal extents in the object's own frame: drop its most vertical axis.
        rot = d.xmat[self._body_id(name)].reshape(3, 3)
        axes = [rot[:, i] for i in np.argsort(np.abs(rot[2, :]))[:2]]
        extents = [float(np.ptp(pts @ a)) for a in axes]
        i_short = int(np.argmin(extents))
        short_dir = axes[i_short][:2] / (np.linalg.norm(axes[i_short][:2]) + 1e-9)
        return Box((low + high) / 2, low, high, short_dir, extents[i_short], extents[1 - i_short])

    # Regions ---------------------------------------------------------------------------------------
    def site_pos(self, name: str) -> np.ndarray:
        return self.sim.data.site_xpos[self.sim.model.site_name2id(name)].copy()

    def site_parent(self, name: str) -> str | None:
        site = self.inner.object_sites_dict.get(name)
        return getattr(site, "parent_name", None)
