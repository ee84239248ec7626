"""Expert episodes rolled out without rendering; what is saved suffices to replay them exactly."""

from dataclasses import dataclass
from xml.etree import ElementTree

import numpy as np

from lerobot_predvla.sims.libero.env import fixture_poses, random_reset
from lerobot_predvla.sims.libero.expert import ExpertFailure
from lerobot_predvla.sims.libero.expert.motion import DEFAULT_HALF_TURN
from lerobot_predvla.sims.libero.expert.teleop import TeleopParams, make_expert
from lerobot_predvla.sims.libero.placement import episode_shift, object_positions, settled

SETTLE_STEPS = 5  # idle steps after reset so objects rest on their support (not recorded)
IDLE = np.array([0, 0, 0, 0, 0, 0, -1.0])


@dataclass
class Episode:
    seed: int
    actions: np.ndarray  # (N, 7) float64
    states: np.ndarray  # (N, S) flattened MuJoCo state before each action
    fixtures: dict[str, tuple[np.ndarray, np.ndarray]]  # fixture body -> (pos, wxyz quat)
    model_xml: str  # the scene, fixture poses included
    success: bool
    note: str = ""


def _model_xml(env, fixtures: dict[str, tuple[np.ndarray, np.ndarray]]) -> str:
    """The loaded scene XML with this reset's fixture poses written into their bodies."""
    root = ElementTree.fromstring(env.sim.model.get_xml())
    for body in root.iter("body"):
        if body.get("name") in fixtures:
            pos, quat = fixtures[body.get("name")]
            body.set("pos", " ".join(f"{v:.9g}" for v in pos))
            body.set("quat", " ".join(f"{v:.9g}" for v in quat))
    return ElementTree.tostring(root, encoding="unicode")


def run_episode(env, seed: int, max_steps: int, half_turn: str = DEFAULT_HALF_TURN,
                init_state: np.ndarray | None = None, hold_steps: int = 0, teleop: TeleopParams | None = None,
                placement_spread: float = 0.0) -> Episode:
    """Randomised reset, then the scripted expert (`half_turn`: HALF_TURN_RULES) until success, then `hold_steps`
    idle steps (arm still, gripper open) recorded after it. With `init_state` (one of the benchmark's official
    evaluation init states) the episode starts there instead: only to measure the expert's success where the
    policies are evaluated, never to record demonstrations. With `teleop` (TeleopParams at a diversity) the
    teleoperator model executes the expert's plan; with `placement_spread` (m, > 0) every movable object is shifted
    after the reset by a seeded offset (placement.py), and an episode whose objects do not settle fails. Both draw
    from generators seeded by `seed` alone."""
    if init_state is None:
        random_reset(env, seed)
    else:
        env.reset()
        env.set_init_state(init_state)
    note = ""
    if placement_spread > 0:
        try:
            episode_shift(env, seed, placement_spread)
        except RuntimeError as err:
            note = str(err)
        placed = object_positions(env)
    for _ in range(SETTLE_STEPS):
        env.step(IDLE)
    fixtures = fixture_poses(env)
    if placement_spread > 0 and not note and not settled(placed, object_positions(env)):
        note = "shifted placement did not settle"
    if note:
        return Episode(seed, np.zeros((0, 7)), np.zeros((0, len(env.get_sim_state()))), fixtures,
                       _model_xml(env, fixtures), False, note)
    actions, states, success = [], [], False
    try:
        expert = make_expert(env, seed, half_turn, teleop)
        for _ in range(max_steps):
            states.append(env.get_sim_state())
            actions.append(expert.act())
            env.step(actions[-1])
            if env.check_success():
                success = True
                for _ in range(hold_steps):  # what follows success, which a policy otherwise never sees
                    states.append(env.get_sim_state())
                    actions.append(IDLE)
                    env.step(IDLE)
                break
            if expert.done:
                note = "plan ended without success"
                break
        else:
            note = f"step cap {max_steps} reached"
    except ExpertFailure as err:
        note = str(err)
    return Episode(seed, np.asarray(actions, dtype=np.float64).reshape(-1, 7),
                   np.asarray(states, dtype=np.float64), fixtures, _model_xml(env, fixtures), success, note)
