"""`predvla_libero`'s randomised-reset starts, reproduced on a bare LIBERO ControlEnv (`predvla blind-replay
--resets-seed`).

`lerobot-eval --env.type=predvla_libero --env.init_states=false --seed=s` starts episode i of every task from the
reset seeded with s + i (`placed_resets`, "Reset seeds"): LeRobot's `LiberoEnv.reset` seeds numpy's global generator
with it (`ControlEnv.seed`), resets the simulator (robosuite draws the fixture poses, LIBERO's object placements and
the arm's start noise from that generator; the evaluation env's ControlEnv has no start noise, magnitude 0, as
`env.make_env` without `init_noise`), then with `--env.placement_spread_cm=S` shifts every movable object
(`placed_resets.PlacedResets.place`, `placement.episode_shift`), then takes `EVAL_SETTLE_STEPS` idle steps.
`eval_start` does the same on a ControlEnv from `env.make_env`, with the same functions, so the simulator is in the
same state when the episode's first action comes (tests/test_placed_resets.py compares the two).
"""

from dataclasses import asdict, dataclass

from lerobot_predvla.sims.libero.env import random_reset
from lerobot_predvla.sims.libero.placed_resets import PlacedResets
from lerobot_predvla.sims.libero.rollout import IDLE

# LeRobot's `LiberoEnv` settles every reset with `num_steps_wait` no-op steps (arm still, gripper open); 10 is its
# default, which `predvla_libero` keeps.
EVAL_SETTLE_STEPS = 10


@dataclass(frozen=True)
class ResetSpec:
    """Which randomised resets: those of `lerobot-eval --seed=seed` for episodes 0 .. episodes - 1, with
    `--env.placement_spread_cm=placement_spread_cm`; `seed` None: none (official init states instead)."""

    seed: int | None = None
    episodes: int = 10
    placement_spread_cm: float = 0.0

    def __post_init__(self) -> None:
        if self.episodes < 1:
            raise ValueError(f"--episodes must be >= 1, got {self.episodes}")
        if not self.placement_spread_cm >= 0:
            raise ValueError(f"--placement-spread-cm must be >= 0 (cm, std per axis), got {self.placement_spread_cm}")
        if self.seed is None and self.placement_spread_cm > 0:
            raise ValueError("--placement-spread-cm shifts the objects after randomised resets: it needs --resets-seed")

    @property
    def active(self) -> bool:
        return self.seed is not None

    def reset_seed(self, episode: int) -> int:
        """The reset seed lerobot-eval gives episode `episode` of every task."""
        return self.seed + episode

    def as_dict(self) -> dict:
        return {**asdict(self), "settle_steps": EVAL_SETTLE_STEPS}


def eval_start(env, seed: int, spread_cm: float = 0.0) -> dict:
    """Put LIBERO ControlEnv `env` (`make_env`, no arm start noise) where `predvla_libero` starts the episode whose
    reset seed is `seed`: the randomised reset, with `spread_cm` > 0 every movable object shifted, the settle steps.
    Returns the episode's record: its seed and, with a spread, the evaluation's placement record
    (`PlacedResets.settle`: offsets, placements, how far each object moved while settling, `settled`)."""
    placements = PlacedResets(spread_cm)
    placements.seed = seed
    random_reset(env, seed)
    if spread_cm > 0:
        placements.place(env)
    for _ in range(EVAL_SETTLE_STEPS):
        env.step(IDLE)
    if spread_cm == 0:
        return {"seed": seed}
    return {k: v for k, v in placements.settle(env).items() if k != "spec"}
