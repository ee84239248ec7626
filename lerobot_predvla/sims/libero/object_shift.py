"""Shifted objects: the object to pick (and, separately, its place target) moved from each official init state.

LIBERO's official init states move the objects by 0-6 mm between episodes, so they cannot tell a policy that looks
from one that replays a memorised motion. `--env.object_shift_cm=d` moves the object to pick by d cm on the table
before each episode of `predvla_libero`, from the official init state the episode starts from; `--env.target_shift_cm`
moves the place target (libero_object's basket) the same way, on its own.

Which objects: the first `In`/`On` predicate of the task's BDDL goal, in the scripted expert's plan order
(`expert.motion.SKILL_ORDER`), names the object to pick and its place; a place that is a region belongs to the object
that carries it (`SceneView.site_parent`, as the expert resolves it): `(In alphabet_soup_1 basket_1_contain_region)`
picks `alphabet_soup_1` and places in `basket_1`.

Direction of episode k (its index in the evaluation, the official init state k mod 50), in the world's x-y plane:
- `ring` (default): angle 360 * k / n degrees, n = `--env.object_shift_directions` (default 8), so every n
  consecutive episodes go once round the ring;
- `cross`: the cycle +x, -x, +y, -y (angles 0, 180, 90, 270), episode k taking entry k mod 4.
The place target's direction is the object's turned by 180 degrees, so that the two moves never cancel.

How: the official init state is set, the offset added to x, y of the body's free joint in qpos, `sim.forward()`, and the
state read back (`sim.get_state().flatten()`); the episode then starts from that state as from an official one. After
the settle steps of every reset the body must rest where it was put: a body that touches another movable object where
it was put, moves more than `--env.shift_tolerance_cm` (default 1 cm) horizontally while settling (it was pushed) or
tilts more than `MAX_TILT_DEG` (it fell over) makes the episode *unsettled*. Height is recorded, not judged: from the
official init states themselves the objects rise or drop 1.4-4 cm as they settle onto the floor. Unsettled episodes
still run and count, and are listed with every shift in `eval_info.json` (`predvla_shifts`, `shift_summary`), so they
are reported, not silently used.
"""

from dataclasses import asdict, dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from lerobot_predvla.sims.libero.expert.motion import SKILL_ORDER
from lerobot_predvla.sims.libero.geometry import SceneView

PATTERNS = ("ring", "cross")
CROSS_DEGREES = (0.0, 180.0, 90.0, 270.0)  # +x, -x, +y, -y
TARGET_TURN_DEGREES = 180.0
PLACE_PREDICATES = ("in", "on")
CM = 0.01
# A shifted body tilted further than this while settling fell over. Settling from the official init states moves the
# objects 1.4-4 cm in height (they start in or above the floor) but tilts them by under 0.3 degrees and moves them
# under 1 mm horizontally (libero_object tasks 0, 2, 3, 6); one pushed 10 cm into a neighbour tilted 40 degrees.
MAX_TILT_DEG = 15.0


@dataclass(frozen=True)
class ShiftSpec:
    """What `--env.object_shift_*` and `--env.target_shift_cm` ask for (all distances in cm)."""

    object_cm: float = 0.0
    target_cm: float = 0.0
    pattern: str = "ring"
    directions: int = 8
    tolerance_cm: float = 1.0

    def __post_init__(self) -> None:
        if self.object_cm < 0 or self.target_cm < 0:
            raise ValueError(f"--env.object_shift_cm and --env.target_shift_cm must be >= 0, got {self.object_cm} "
                             f"and {self.target_cm}.")
        if self.pattern not in PATTERNS:
            raise ValueError(f"--env.object_shift_pattern must be one of {PATTERNS}, got {self.pattern!r}.")
        if self.directions < 1:
            raise ValueError(f"--env.object_shift_directions must be >= 1, got {self.directions}.")
        if self.tolerance_cm <= 0:
            raise ValueError(f"--env.shift_tolerance_cm must be > 0, got {self.tolerance_cm}.")

    @property
    def active(self) -> bool:
        return self.object_cm > 0 or self.target_cm > 0

    def check_init_states(self, init_states: bool) -> None:
        """ValueError naming the flags when a shift is asked for without the official init states it starts from."""
        if self.active and not init_states:
            raise ValueError("--env.object_shift_cm / --env.target_shift_cm move objects from the official init "
                             "states: they need --env.init_states=true.")

    def direction_degrees(self, episode: int) -> float:
        """Direction (degrees from +x towards +y) of the object's shift in episode `episode`."""
        if self.pattern == "cross":
            return CROSS_DEGREES[episode % len(CROSS_DEGREES)]
        return 360.0 * (episode % self.directions) / self.directions

    def offsets(self, episode: int) -> dict[str, tuple[float, np.ndarray]]:
        """{"object" | "target": (direction in degrees, xy offset in m)} for the bodies this spec moves."""
        angle = self.direction_degrees(episode)
        out = {}
        for role, cm, degrees in (("object", self.object_cm, angle), ("target", self.target_cm,
                                                                       (angle + TARGET_TURN_DEGREES) % 360.0)):
            if cm > 0:
                radians = np.deg2rad(degrees)
                out[role] = (degrees, cm * CM * np.array([np.cos(radians), np.sin(radians)]))
        return out


def pick_and_place(goal: list) -> tuple[str, str]:
    """(object to pick, place) of a parsed BDDL goal (`parsed_problem["goal_state"]`): the first `In`/`On`
    predicate in the scripted expert's plan order."""
    for predicate, *args in sorted((tuple(p) for p in goal), key=lambda p: SKILL_ORDER.get(p[0], len(SKILL_ORDER))):
        if predicate in PLACE_PREDICATES:
            return args[0], args[1]
    raise ValueError(f"the task's goal {goal} has no In/On predicate: it names no object to pick, so nothing to shift.")


def shifted_bodies(env) -> dict[str, str]:
    """{"object": object to pick, "target": the movable object it is placed in or on} of a LIBERO ControlEnv; no
    "target" when the place is a fixture or a table region."""
    view = SceneView(env)
    obj, place = pick_and_place(env.env.parsed_problem["goal_state"])
    owner = view.site_parent(place) if place in view.inner.object_sites_dict else place
    bodies = {"object": obj}
    if owner in view.inner.objects_dict:
        bodies["target"] = owner
    return bodies


def free_joint_address(env, name: str) -> int:
    """qpos address of movable object `name`'s free joint (x, y, z, then its quaternion)."""
    joints = env.env.objects_dict[name].joints
    if not joints:
        raise ValueError(f"object {name!r} has no free joint, so it cannot be shifted.")
    return env.sim.model.get_joint_qpos_addr(joints[0])[0]


def shifted_state(env, state: np.ndarray, moves: dict[str, np.ndarray]) -> np.ndarray:
    """Flattened simulator state `state` with each object of `moves` ({name: xy offset in m}) moved on x, y."""
    sim = env.sim
    sim.set_state_from_flattened(state)
    sim.forward()
    for name, offset in moves.items():
        address = free_joint_address(env, name)
        sim.data.qpos[address:address + 2] += offset
    sim.forward()
    return sim.get_state().flatten()


def touching(env, name: str) -> list[str]:
    """The other movable objects that object `name` is in contact with (penetrating or touching) now."""
    inner, model, data = env.env, env.sim.model._model, env.sim.data._data
    roots = {int(model.body_rootid[inner.obj_body_id[n]]): n for n in inner.objects_dict}
    own = int(model.body_rootid[inner.obj_body_id[name]])
    found = set()
    for contact in data.contact[: data.ncon]:
        a, b = (int(model.body_rootid[model.geom_bodyid[g]]) for g in (contact.geom1, contact.geom2))
        if own in (a, b):
            other = b if a == own else a
            if other != own and other in roots:
                found.add(roots[other])
    return sorted(found)


def pose(env, name: str) -> np.ndarray:
    """Position (3) and quaternion (4, wxyz) of movable object `name`'s free joint."""
    address = free_joint_address(env, name)
    return env.sim.data.qpos[address:address + 7].copy()


def settle_motion(placed: np.ndarray, settled: np.ndarray) -> dict[str, float]:
    """How a body moved while settling, from its free-joint pose where it was put to its pose after: horizontal motion
    (cm), height change (cm) and tilt (degrees between its vertical axes)."""
    up = Rotation.from_quat(np.stack([placed[3:], settled[3:]]), scalar_first=True).apply([0.0, 0.0, 1.0])
    tilt = np.degrees(np.arccos(np.clip(up[0] @ up[1], -1.0, 1.0)))
    return {"xy_cm": round(float(np.linalg.norm(settled[:2] - placed[:2])) / CM, 3),
            "dz_cm": round(float(settled[2] - placed[2]) / CM, 3), "tilt_deg": round(float(tilt), 2)}


def shift_summary(envs: dict) -> dict | None:
    """The `predvla_shifts` section of eval_info.json: every shifted episode (suite, task, episode, init state, and per
    shifted body its name, distance, direction, offset and whether it settled), and the unsettled count; None when
    no environment shifted anything."""
    records = []
    for suite, tasks in envs.items():
        for vec_env in tasks.values():
            try:
                per_env = vec_env.get_attr("shift_records")
            except AttributeError:  # not a predvla_libero env
                continue
            records += [{"suite": suite, **record} for episodes in per_env for record in episodes]
    if not records:
        return None
    records.sort(key=lambda r: (r["suite"], r["task_id"], r["episode_ix"]))
    unsettled = [{k: r[k] for k in ("suite", "task_id", "episode_ix")} for r in records if not r["settled"]]
    return {"spec": records[0]["spec"], "episodes": [{k: v for k, v in r.items() if k != "spec"} for r in records],
            "unsettled_episodes": unsettled}


@dataclass
class BodyShift:
    """One body moved at one reset: where it was put (free-joint pose), what it touched there, and how it settled."""

    role: str
    name: str
    distance_cm: float
    direction_deg: float
    offset_m: list[float]
    placed: list[float]
    touching: list[str]
    settle: dict[str, float] | None = None

    def settled(self, tolerance_cm: float) -> bool:
        return (not self.touching and self.settle is not None and self.settle["xy_cm"] <= tolerance_cm
                and self.settle["tilt_deg"] <= MAX_TILT_DEG)


class ShiftedResets:
    """Moves the bodies of `spec` in one LIBERO ControlEnv at each reset and checks that they settle."""

    def __init__(self, spec: ShiftSpec) -> None:
        self.spec = spec
        self._bodies: dict[str, str] | None = None
        self._pending: list[BodyShift] = []

    def bodies(self, env) -> dict[str, str]:
        if self._bodies is None:
            self._bodies = shifted_bodies(env)
            if self.spec.target_cm > 0 and "target" not in self._bodies:
                raise ValueError("--env.target_shift_cm: this task places its object on a fixture or a table region, "
                                 "not in or on a movable object, so there is no place target to shift.")
        return self._bodies

    def shifted(self, env, state: np.ndarray, episode: int) -> np.ndarray:
        """Official init state `state` with this episode's shifts applied (remembered for `settle`)."""
        bodies = self.bodies(env)
        offsets = self.spec.offsets(episode)
        new = shifted_state(env, state, {bodies[role]: offset for role, (_, offset) in offsets.items()})
        self._pending = []
        for role, (degrees, offset) in offsets.items():
            name = bodies[role]
            cm = self.spec.object_cm if role == "object" else self.spec.target_cm
            self._pending.append(BodyShift(role, name, cm, round(degrees, 3), offset.round(6).tolist(),
                                           pose(env, name).round(6).tolist(), touching(env, name)))
        return new

    def settle(self, env) -> dict:
        """After the reset's settle steps: each shifted body's motion since it was put, and the episode's verdict."""
        for body in self._pending:
            body.settle = settle_motion(np.asarray(body.placed), pose(env, body.name))
        return {"spec": asdict(self.spec), "bodies": [asdict(b) for b in self._pending],
                "settled": all(b.settled(self.spec.tolerance_cm) for b in self._pending)}
