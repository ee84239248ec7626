"""A task only observations can solve: reach one of K targets whose identity is seen, never told.

Every episode has the same instruction. The target is drawn from K places on a circle; the visual features carry a
fixed code of the target at every step, and proprioception is the point's position. Exact open loop never reads an
observation (Section 3.5), so one instruction gives one trajectory: it can reach at most one of the K targets, a
success rate of at most 1/K by construction. Error regression reads the code through the visual prediction error
(Eqs. 7-9) and can steer the actions to the right target only if training made the posteriors that explain the
visual features also drive the action branch: the mechanism the paper claims.

`train_policy` trains the real `PredVLAPolicy` (its `forward`, posterior store and `update`) on demonstrations of a
proportional expert, and `success_rate` acts with its `select_action`, the same error regression `lerobot-eval`
runs. A small network and short episodes make a training take seconds on one core (`tests/test_mechanism.py`).

Command (from the repository root): `python -m research.mechanism` trains a small PredVLA on the reach task for each
training reading (`--reading name:field=value,...`; the bare defaults are Table 2's readings) and evaluates each with
exact open loop and every error-regression reading (`--er name:field=value,...`), paired on the same episodes. It
prints success, the visual prediction error of the chain that acted, and where the training posteriors put the target
(the fraction of episodes that follow another target's posteriors when only one module's are swapped in), and writes
the same as JSON with `--out`.
"""

import argparse
import json
import math
import re
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import torch
from lerobot.utils.constants import OBS_STATE
from torch import Tensor

from lerobot_predvla.columns import OBS_LANGUAGE_FEATURES, OBS_VISION_FEATURES
from lerobot_predvla.policies.common.sequence_table import EpisodeSequences
from lerobot_predvla.policies.predvla.configuration_predvla import MODULE_NAMES, PredVLAConfig
from lerobot_predvla.policies.predvla.modeling_predvla import PredVLAPolicy
from lerobot_predvla.utils.io import atomic_write_json
from lerobot_predvla.utils.versions import run_versions


@dataclass(frozen=True)
class ReachTask:
    """K targets on a circle around the start; a point moved by velocity actions in [-1, 1].

    Args:
        num_targets: K; open loop succeeds in at most 1/K of the episodes.
        length: Control steps per episode (the expert arrives in about half of them and then holds still).
        wait_steps: Steps at the start in which the expert holds still while the code is already visible: the
            time error regression has to read it before the first move (a LIBERO policy sees its scene before
            its arm reaches anything; without a wait the demonstrations' first action already needs the target).
        dt: Position change per unit action and step.
        gain: The expert's proportional gain, action = clip(gain (target - position), -1, 1).
        code_dim: Size of the visual features, a fixed random code per target (unit variance).
        start_noise: Standard deviation of the start position around the centre.
        success_radius: An episode succeeds if it ends within this distance of its target.
        seed: Seed of the codes.
    """

    num_targets: int = 4
    length: int = 24
    wait_steps: int = 6
    dt: float = 0.15
    gain: float = 2.0
    code_dim: int = 8
    start_noise: float = 0.05
    success_radius: float = 0.3
    seed: int = 0

    @property
    def targets(self) -> Tensor:
        angles = torch.arange(self.num_targets, dtype=torch.float32) * (2 * math.pi / self.num_targets) + math.pi / 4
        return torch.stack([angles.cos(), angles.sin()], dim=-1)

    @property
    def codes(self) -> Tensor:
        return torch.randn(self.num_targets, self.code_dim, generator=torch.Generator().manual_seed(self.seed))

    def starts(self, targets: Tensor, generator: torch.Generator) -> Tensor:
        return self.start_noise * torch.randn(len(targets), 2, generator=generator)

    def expert_action(self, position: Tensor, target: Tensor) -> Tensor:
        return (self.gain * (target - position)).clamp(-1.0, 1.0)

    def move(self, position: Tensor, action: Tensor) -> Tensor:
        return position + self.dt * action.clamp(-1.0, 1.0)

    def demonstrations(self, per_target: int, seed: int) -> tuple[EpisodeSequences, Tensor]:
        """`per_target` expert episodes per target as the in-memory table `PredVLAPolicy` trains on, and each
        episode's target index."""
        generator = torch.Generator().manual_seed(seed)
        which = torch.arange(self.num_targets).repeat_interleave(per_target)
        goal = self.targets[which]
        position = self.starts(which, generator)
        states, actions = [], []
        for t in range(self.length):
            action = self.expert_action(position, goal) if t >= self.wait_steps else torch.zeros_like(position)
            states.append(position)
            actions.append(action)
            position = self.move(position, action)
        n = len(which)
        sequences = EpisodeSequences(
            vision=self.codes[which][:, None].expand(n, self.length, self.code_dim).clone(),
            state=torch.stack(states, dim=1),
            action=torch.stack(actions, dim=1),
            language=torch.zeros(n, 1),
            length=torch.full((n,), self.length),
        )
        return sequences, which


def task_config(task: ReachTask, **overrides) -> PredVLAConfig:
    """A small PredVLA for `task`: the paper's structure, time constants and inference settings at a width that
    trains in seconds. Overrides are `PredVLAConfig` fields (the readings being compared)."""
    fields = {
        "vision_dim_per_camera": task.code_dim, "num_cameras": 1, "proprio_dim": 2, "action_dim": 2,
        "language_dim": 1, "module_dims": (16, 32, 32, 32), "latent_dim": 8, "bottleneck_dim": 8,
        "head_hidden_dim": 32, "num_mixtures": 2, "visual_refresh_interval": 1, "sequence_length": task.length,
        "er_window": task.length, "optimizer_lr": 3e-3, "recurrence_backend": "python", "device": "cpu",
        "push_to_hub": False,
    }
    fields.update(overrides)
    return PredVLAConfig(**fields)


@dataclass
class TrainingRecord:
    """The training demonstrations' target indices (rows of the posterior store) and the loss at every step."""

    targets: Tensor
    losses: list[float] = field(default_factory=list)


def train_policy(task: ReachTask, config: PredVLAConfig, steps: int, per_target: int = 16, seed: int = 0
                 ) -> tuple[PredVLAPolicy, TrainingRecord]:
    """Train `PredVLAPolicy` as `lerobot-train` does (its `forward`, Adam on the network with the config's
    preset and gradient clip, then `update` for the posteriors), on full batches of the task's demonstrations."""
    torch.manual_seed(seed)
    policy = PredVLAPolicy(config)
    sequences, targets = task.demonstrations(per_target, seed)
    policy.train_on(sequences)
    preset = config.get_optimizer_preset()
    optimizer = torch.optim.Adam(policy.network_parameters(), lr=preset.lr, betas=preset.betas, eps=preset.eps,
                                 weight_decay=preset.weight_decay)
    batch = {"episode_index": torch.arange(len(sequences.length))}
    record = TrainingRecord(targets)
    policy.train()
    for _ in range(steps):
        loss, _ = policy.forward(batch)
        optimizer.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(policy.network_parameters(), preset.grad_clip_norm)
        optimizer.step()
        policy.update()
        record.losses.append(loss.item())
    policy.eval()
    return policy, record


class Outcome(NamedTuple):
    """What a batch of episodes did: final positions (episodes, 2), each episode's target index, and the mean
    per-dimension visual prediction error of the chain that produced the actions (Eq. 7): the window's
    regenerated states under error regression, the prior chain in exact open loop."""

    position: Tensor
    target: Tensor
    visual_error: float


@torch.no_grad()
def rollout(task: ReachTask, policy: PredVLAPolicy, episodes_per_target: int, seed: int, **overrides) -> Outcome:
    """Act in the task with `select_action` for a batch of episodes (every target equally often), with the
    config fields in `overrides` (e.g. `er_iterations=0`, exact open loop) set for the rollout only."""
    saved = {k: getattr(policy.config, k) for k in overrides}
    for k, v in overrides.items():
        setattr(policy.config, k, v)
    try:
        generator = torch.Generator().manual_seed(seed)
        which = torch.arange(task.num_targets).repeat(episodes_per_target)
        position = task.starts(which, generator)
        code, language = task.codes[which], torch.zeros(len(which), 1)
        policy.reset()
        for _ in range(task.length):
            observation = {OBS_VISION_FEATURES: code, OBS_STATE: position, OBS_LANGUAGE_FEATURES: language}
            position = task.move(position, policy.select_action(observation))
        model, er = policy.model, policy.error_regression
        if er.posteriors:  # error regression: the window (the whole episode) at its inferred posteriors
            chain = model.rollout(er.start_state, er.lang_term, torch.stack(er.posteriors))
        else:  # exact open loop: the prior chain it acted from
            chain = model.rollout(model.initial_state(len(which)), model.language_term(language), steps=task.length)
        steps = chain.d[0].shape[0]
        visual_error = float(model.prediction_errors(chain, code.expand(steps, -1, -1), chain.q_hat)[0].mean())
        return Outcome(position, which, visual_error)
    finally:
        for k, v in saved.items():
            setattr(policy.config, k, v)
        policy.reset()


def success_rate(outcome: Outcome, task: ReachTask) -> float:
    """Fraction of episodes that end within `success_radius` of their own target."""
    distance = (outcome.position - task.targets[outcome.target]).norm(dim=-1)
    return float((distance < task.success_radius).float().mean())


@torch.no_grad()
def follows_swapped_posteriors(task: ReachTask, policy: PredVLAPolicy, record: TrainingRecord,
                               modules: tuple[int, ...]) -> float:
    """Where the actions' target lives in the training posteriors: each demonstration is rolled out from its own
    training posteriors except those of `modules` (indices into T, V, A_top, A_bottom), taken from a demonstration of
    the next target; returns the fraction of episodes that end at that other target."""
    sequences, which = policy.sequences, record.targets
    model, r = policy.model, policy.config.latent_dim
    c_q = policy.posterior_store.latents.transpose(0, 1).unflatten(-1, (4, r))  # (time, episodes, module, r)
    donor = torch.stack([(which == (k + 1) % task.num_targets).nonzero()[0, 0] for k in which.tolist()])
    mixed = c_q.clone()
    mixed[:, :, list(modules)] = c_q[:, donor][:, :, list(modules)]
    chain = model.rollout(model.initial_state(len(which)), model.language_term(sequences.language), mixed.flatten(-2))
    position = sequences.state[:, 0]
    for action in chain.a_hat.unbind(0):
        position = task.move(position, action)
    other = task.targets[which[donor]]
    return float(((position - other).norm(dim=-1) < task.success_radius).float().mean())


def reading(text: str) -> tuple[str, dict]:
    """"name:field=value,field=value" -> (name, {field: value}) with values parsed as JSON where they parse (a list
    such as complexity_weights=[0.05,0.02,1,1] keeps its commas)."""
    name, _, body = text.partition(":")
    fields = {}
    for item in filter(None, re.split(r",(?![^\[\]]*\])", body)):
        key, sep, value = item.partition("=")
        if not sep:
            raise argparse.ArgumentTypeError(f"{text!r}: expected name:field=value,... (got {item!r})")
        try:
            fields[key] = json.loads(value)
        except json.JSONDecodeError:
            fields[key] = value
    return name, fields


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m research.mechanism", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=600, help="Training steps per reading (full batches).")
    parser.add_argument("--reading", type=reading, action="append", default=None,
                        help="A training reading, name:field=value,... (repeatable; default: table2, no fields).")
    parser.add_argument("--er", type=reading, action="append", default=None,
                        help="An error-regression reading, name:field=value,... (repeatable; default: Table 2's).")
    parser.add_argument("--episodes-per-target", type=int, default=10)
    parser.add_argument("--seed", type=int, default=0, help="Training seed (evaluation episodes: seed 1000).")
    parser.add_argument("--out", type=Path, default=None, help="Write the table as JSON here.")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    torch.set_num_threads(1)
    task = ReachTask()
    readings = args.reading or [("table2", {})]
    er_readings = [("open_loop", {"er_iterations": 0}), *(args.er or [("table2_er", {})])]
    rows = []
    for name, fields in readings:
        start = time.perf_counter()
        policy, record = train_policy(task, task_config(task, **fields), args.steps, seed=args.seed)
        swapped = {m: follows_swapped_posteriors(task, policy, record, (i,)) for i, m in enumerate(MODULE_NAMES)}
        for er_name, er_fields in er_readings:
            outcome = rollout(task, policy, args.episodes_per_target, 1000, **er_fields)
            rows.append({"reading": name, "fields": fields, "inference": er_name, "inference_fields": er_fields,
                         "success": success_rate(outcome, task), "visual_error": outcome.visual_error,
                         "follows_swapped": swapped, "final_loss": record.losses[-1],
                         "train_s": round(time.perf_counter() - start, 1)})
            follows = " ".join(f"{m} {v:.2f}" for m, v in swapped.items())
            print(f"{name:16s} {er_name:18s} success {rows[-1]['success']:.2f}  visual error "
                  f"{outcome.visual_error:.3f}  follows swapped {follows}", flush=True)
    print(f"chance: {1 / task.num_targets:.2f} (open loop can reach at most one of {task.num_targets} targets)")
    if args.out is not None:
        # Training's arithmetic, and so every row, can differ between installations: the file says which made it.
        atomic_write_json(args.out, {"task": vars(task), "steps": args.steps, "seed": args.seed,
                                     "versions": run_versions(), "rows": rows})
    return 0


if __name__ == "__main__":
    sys.exit(main())
