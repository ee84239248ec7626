"""Object placements moved away from where LIBERO put them (`predvla demos --placement-spread-cm`).

After a reset (a randomised one, or an official init state set), `shift_objects` adds an x, y offset to the free joint
of each named movable object and recomputes the simulation (`sim.forward()`); nothing else of the state changes.
`shifted_start` draws the offsets from a seeded generator and redraws where a shifted object would overlap another
object, a fixture or the robot; after the episode's settle steps `settled` checks that the objects came to rest
where they were put. `episode_shift` is one episode's shift, seeded by its reset seed alone: `predvla demos
--placement-spread-cm` and `lerobot-eval --env.placement_spread_cm` both call it, so a demonstration and an evaluation
episode whose resets have the same seed start from the same shifted placement. The shifts are what a policy needs to
see for its actions to depend on where the objects are: LIBERO's placement regions on libero_object spread the
objects by only a few millimetres.
"""

from collections.abc import Mapping

import numpy as np

PLACEMENT_STREAM = 85  # the placement generator is seeded with (episode seed, PLACEMENT_STREAM)
MAX_DRAWS = 50  # offsets drawn before giving up on a start
OVERLAP = 0.002  # m: a shifted object's contact this deep with what it did not touch before is an overlap
SETTLE_TOLERANCE = 0.01  # m: how far an object may move during the settle steps and still count as at rest


def movable_objects(env) -> list[str]:
    """LIBERO's movable objects of the task (`objects_dict`), in its order."""
    return list(env.env.objects_dict)


def object_positions(env, names: list[str] | None = None) -> np.ndarray:
    """World x, y, z of the body of each object in `names` (default: every movable object), shape (n, 3)."""
    inner = env.env
    names = movable_objects(env) if names is None else names
    return np.array([inner.sim.data.body_xpos[inner.obj_body_id[name]] for name in names])


def shift_objects(env, offsets: Mapping[str, np.ndarray]) -> None:
    """Move each named object by its x, y offset (m): added to the x, y of its free joint in qpos, then
    `sim.forward()`. The orientation, the height and every other joint stay as they were."""
    inner = env.env
    for name, offset in offsets.items():
        if name not in inner.objects_dict:
            raise KeyError(f"{name!r} is not a movable object of this task; expected one of {movable_objects(env)}")
        offset = np.asarray(offset, dtype=float)
        if offset.shape != (2,):
            raise ValueError(f"offset of {name!r} must be (dx, dy) in m, got shape {offset.shape}")
        start, _ = inner.sim.model.get_joint_qpos_addr(inner.objects_dict[name].joints[0])
        inner.sim.data.qpos[start:start + 2] += offset
    inner.sim.forward()


def _body_owner(env) -> np.ndarray:
    """For each MuJoCo body, the index of the movable object whose subtree it belongs to, or -1."""
    model = env.sim.model
    owner = np.full(model.nbody, -1)
    roots = {env.env.obj_body_id[name]: i for i, name in enumerate(movable_objects(env))}
    for body in range(model.nbody):
        b = body
        while b > 0 and b not in roots:
            b = model.body_parentid[b]
        owner[body] = roots.get(b, -1)
    return owner


def _touching(env, names: list[str], depth: float = 0.0) -> set[tuple[str, int]]:
    """(object, other body) pairs joined by a contact deeper than `depth` (m), for the objects of `names`; bodies of
    one object count as that object (-1 - body id for bodies of no object)."""
    sim, owner = env.sim, _body_owner(env)
    objects = movable_objects(env)
    pairs = set()
    for contact in sim.data.contact[: sim.data.ncon]:
        if contact.dist > -depth:
            continue
        a, b = (int(sim.model.geom_bodyid[g]) for g in (contact.geom1, contact.geom2))
        for mine, other in ((a, b), (b, a)):
            if owner[mine] >= 0 and objects[owner[mine]] in names and owner[other] != owner[mine]:
                pairs.add((objects[owner[mine]], int(owner[other]) if owner[other] >= 0 else -1 - other))
    return pairs


def overlapping(env, names: list[str], before: set[tuple[str, int]]) -> list[str]:
    """Objects of `names` that a contact deeper than OVERLAP joins to something they did not touch at all before the
    shift (`before`, from `_touching`): another object, a fixture, the robot, but not the table they stood on."""
    return sorted({name for name, other in _touching(env, names, OVERLAP) if (name, other) not in before})


def shifted_start(env, rng: np.random.Generator, spread: float,
                  names: list[str] | None = None) -> dict[str, np.ndarray]:
    """Shift every object of `names` (default: all movable ones) by an offset drawn per axis from N(0, spread)
    truncated at 2 spread (m); redraw all of them (up to MAX_DRAWS times) while one overlaps something. Returns the
    offsets applied. Raises RuntimeError when no draw fits."""
    names = movable_objects(env) if names is None else names
    state = env.sim.get_state()
    before = _touching(env, names)
    for _ in range(MAX_DRAWS):
        offsets = {name: np.clip(rng.normal(0.0, spread, 2), -2 * spread, 2 * spread) for name in names}
        shift_objects(env, offsets)
        if not overlapping(env, names, before):
            return offsets
        env.sim.set_state(state)
        env.sim.forward()
    raise RuntimeError(f"no placement with spread {spread} m in {MAX_DRAWS} draws left every object free")


def episode_shift(env, seed: int, spread: float) -> dict[str, np.ndarray]:
    """`shifted_start` of every movable object at `spread` (m) for the episode whose reset seed is `seed`: the
    generator is seeded with (seed, PLACEMENT_STREAM), so the offsets depend on the seed (and its reset) only."""
    return shifted_start(env, np.random.default_rng([seed, PLACEMENT_STREAM]), spread)


def settled(before: np.ndarray, after: np.ndarray) -> bool:
    """Whether objects at `before` (object_positions right after the shift) are within SETTLE_TOLERANCE of it in
    x, y after the settle steps (`after`). Height is not compared: a reset leaves objects a few cm above or inside
    their support, and they drop or rise onto it in the settle steps whether shifted or not."""
    return bool(np.all(np.linalg.norm(after[:, :2] - before[:, :2], axis=1) < SETTLE_TOLERANCE))
