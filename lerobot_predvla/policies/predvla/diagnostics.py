"""What a researcher looks at first on a PredVLA checkpoint (`predvla inspect`).

Everything is computed offline against the training dataset's cached columns, without the simulator:

- open-loop actions (Section 3.5, n_itr = 0: every posterior at its prior) per task against the task's
  time-aligned mean demonstration, and against every other task's: does the instruction pick the behaviour?
- the language swap: the same open-loop chain driven by each other task's instruction, and how far the
  actions move; the drive of the language term W_lang l (Eq. 4) and of its differences between tasks;
- the training posteriors c_q (Eq. 10) per module: their size, their per-task means against the spread
  within a task, and their gap to the priors c_p (Eqs. 1-2) along the training rollout;
- the proprioceptive prediction error per dimension (Eq. 7), open loop and from the training posteriors;
- error regression replayed on one demonstration per task (its own observations, step by step as when
  acting): per-step prediction errors (Eq. 7), prior-posterior gap per module (Eq. 8), free energy (Eq. 9),
  and its actions against the demonstrated ones next to the open-loop chain's.
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from lerobot.datasets.lerobot_dataset import LeRobotDatasetMetadata
from lerobot.utils.constants import ACTION
from safetensors.torch import load_file
from torch import Tensor

from lerobot_predvla.utils.io import atomic_write_json

from .configuration_predvla import MODULE_NAMES
from .error_regression import ErrorRegression
from .modeling_predvla import PredVLAPolicy
from .posterior_store import POSTERIOR_STORE_FILE
from .sequence_table import EpisodeSequences, read_columns


@dataclass
class TaskData:
    """The training dataset grouped by task: episodes, names, time-aligned mean demonstrations."""

    sequences: EpisodeSequences
    names: list[str]  # task string per task index
    episodes: list[list[int]]  # episode indices per task index
    mean_action: Tensor  # (tasks, L, action_dim), normalised units, NaN past the longest demonstration
    action_low: Tensor  # min-max statistics: raw = (x + 1) / 2 * (high - low) + low
    action_high: Tensor

    @classmethod
    def load(cls, root: Path, policy: PredVLAPolicy) -> "TaskData":
        meta = LeRobotDatasetMetadata("local/inspect", root=root)
        stats = {k: {s: torch.as_tensor(np.asarray(v)) for s, v in d.items()} for k, d in meta.stats.items()}
        sequences = EpisodeSequences.from_dataset(root, policy.config, stats)
        columns = read_columns(root, ["episode_index", "task_index"])
        task_of = {int(e): int(t) for e, t in zip(columns["episode_index"][:, 0], columns["task_index"][:, 0],
                                                   strict=True)}
        names = [""] * (max(task_of.values()) + 1)
        for name, row in meta.tasks.iterrows():
            names[int(row["task_index"])] = str(name)
        episodes = [[e for e, t in sorted(task_of.items()) if t == task] for task in range(len(names))]
        valid = (torch.arange(sequences.action.shape[1])[None] < sequences.length[:, None]).float()[..., None]
        mean_action = torch.stack([
            (sequences.action[eps] * valid[eps]).sum(0) / valid[eps].sum(0) for eps in episodes
        ])  # 0/0 = NaN where no demonstration of the task is that long
        return cls(sequences, names, episodes, mean_action, stats[ACTION]["min"].float(),
                   stats[ACTION]["max"].float())

    def raw(self, action: Tensor) -> Tensor:
        return (action + 1) / 2 * (self.action_high - self.action_low) + self.action_low

    def horizon(self, task: int) -> int:
        """Mean demonstration length of a task: the steps the action comparisons run over."""
        return int(self.sequences.length[self.episodes[task]].float().mean().round())


def action_mse(a: Tensor, b: Tensor) -> float:
    """Mean squared difference over the steps where both are defined."""
    ok = ~(a.isnan() | b.isnan()).any(-1)
    return float((a[ok] - b[ok]).pow(2).mean())


@torch.no_grad()
def open_loop(policy: PredVLAPolicy, language: Tensor, steps: int) -> Tensor:
    """Exact open-loop actions (time, batch, action_dim), normalised: posteriors at their priors."""
    model = policy.model
    return model.rollout(model.initial_state(len(language)), model.language_term(language), steps=steps).a_hat


@torch.no_grad()
def language_report(policy: PredVLAPolicy, data: TaskData) -> dict:
    """Open loop per task against the mean demonstrations, the language swap and the language drive."""
    n, steps = len(data.names), data.sequences.action.shape[1]
    language = torch.stack([data.sequences.language[eps[0]] for eps in data.episodes])
    actions = open_loop(policy, language, steps).transpose(0, 1)  # (tasks, L, A): task i under instruction i
    raw_actions, raw_means = data.raw(actions), data.raw(data.mean_action)
    vs_demo = [[action_mse(raw_actions[i, :data.horizon(i)], raw_means[j, :data.horizon(i)]) for j in range(n)]
               for i in range(n)]
    swap = [[action_mse(raw_actions[i, :data.horizon(i)], raw_actions[j, :data.horizon(i)]) for j in range(n)]
            for i in range(n)]
    demo_gap = [[action_mse(raw_means[i, :data.horizon(i)], raw_means[j, :data.horizon(i)]) for j in range(n)]
                for i in range(n)]
    # How far a task's own demonstrations lie from their mean: what no observation-blind chain can get below, and
    # a measure of how much the task's actions depend on what the robot sees (e.g. aligning to an object's yaw).
    spread = []
    for i in range(n):
        steps = [min(int(data.sequences.length[e]), data.horizon(i)) for e in data.episodes[i]]
        spread.append(float(np.mean([action_mse(data.raw(data.sequences.action[e, :k]), raw_means[i, :k])
                                     for e, k in zip(data.episodes[i], steps, strict=True)])))
    identified = [int(np.argmin(row)) == i for i, row in enumerate(vs_demo)]
    drive = policy.model.language_term(language)  # W_lang l (Eq. 4)
    diffs = [float((drive[i] - drive[j]).norm()) for i in range(n) for j in range(i + 1, n)]
    off = ~np.eye(n, dtype=bool)
    return {
        "open_loop_actions": actions,
        "open_loop_mse_own_task": [vs_demo[i][i] for i in range(n)],
        "open_loop_mse_nearest_other_task": [min(vs_demo[i][j] for j in range(n) if j != i) if n > 1 else None
                                             for i in range(n)],
        "open_loop_picks_own_task": sum(identified) / n,
        "demo_spread_mse": spread,
        "open_loop_vs_mean_demos": vs_demo,
        "language_swap_mse": swap,
        "mean_demo_gap_mse": demo_gap,
        "mean_language_swap_mse": float(np.asarray(swap)[off].mean()) if n > 1 else 0.0,
        "mean_demo_gap": float(np.asarray(demo_gap)[off].mean()) if n > 1 else 0.0,
        "language_drive_norm": float(drive.norm(dim=-1).mean()),
        "language_difference_drive_norm": float(np.mean(diffs)) if diffs else 0.0,
    }


def posterior_report(policy: PredVLAPolicy, data: TaskData, store: Tensor) -> dict:
    """Training posteriors per module: size, per-task means against the spread within a task, prior gap."""
    r, seq = policy.config.latent_dim, data.sequences
    valid = torch.arange(store.shape[1])[None] < seq.length[:, None]  # (E, L)
    per_module = store.unflatten(-1, (4, r))  # (E, L, 4, r)
    out: dict[str, dict] = {}
    task_means = []
    for eps in data.episodes:
        v = valid[eps].float()[..., None, None]
        task_means.append((per_module[eps] * v).sum(0) / v.sum(0).clamp_min(1))  # (L, 4, r)
    task_means = torch.stack(task_means)  # (tasks, L, 4, r)
    with torch.no_grad():
        model, e = policy.model, torch.arange(store.shape[0])
        batch = seq.batch(e, torch.device("cpu"))
        traj = model.rollout(model.initial_state(len(e)), model.language_term(batch["language"]),
                             store.transpose(0, 1))
        gap = (store.transpose(0, 1) - model.priors(traj)).unflatten(-1, (4, r)).norm(dim=-1)  # (L, E, 4)
    gap_valid = valid.T.float()[..., None]
    for m, name in enumerate(MODULE_NAMES):
        norms = per_module[..., m, :].norm(dim=-1)[valid]
        within = torch.cat([(per_module[eps][..., m, :] - task_means[t, :, m])[valid[eps]].norm(dim=-1)
                            for t, eps in enumerate(data.episodes)])
        between = [float((task_means[i, :, m] - task_means[j, :, m]).norm(dim=-1).mean())
                   for i in range(len(task_means)) for j in range(i + 1, len(task_means))]
        out[name] = {
            "mean_norm": float(norms.mean()),
            "within_task_spread": float(within.mean()),
            "between_task_mean_distance": float(np.mean(between)) if between else 0.0,
            "prior_gap": float((gap[..., m:m + 1] * gap_valid).sum() / gap_valid.sum()),
        }
    return out


@torch.no_grad()
def proprio_report(policy: PredVLAPolicy, data: TaskData, store: Tensor | None) -> dict:
    """Eq. 7's eps_q per proprioceptive dimension (normalised units, every training episode's valid steps).

    Of the exact open-loop chain and, where the checkpoint has them, of the rollout from each demonstration's
    own training posteriors; beside them the demonstrations' spread around their task's time-aligned mean state,
    which no observation-blind chain can get below. Posteriors that explain how demonstrations differ bring the
    second well below the first: `removed` is the fraction of the open-loop eps_q and eps_v (the latter on visual
    refresh steps) that the posteriors remove, 1 - posteriors / open loop.
    """
    model, seq = policy.model, data.sequences
    batch = seq.batch(torch.arange(seq.state.shape[0]), torch.device("cpu"))
    valid, state = batch["valid"], batch["state"]  # (L, E), (L, E, P)
    fresh = valid & (torch.arange(valid.shape[0])[:, None] % policy.config.visual_refresh_interval == 0)
    lang_term = model.language_term(batch["language"])
    trajectories = {"open_loop": model.rollout(model.initial_state(valid.shape[1]), lang_term, steps=valid.shape[0])}
    if store is not None:
        trajectories["posteriors"] = model.rollout(model.initial_state(valid.shape[1]), lang_term,
                                                   store.transpose(0, 1))
    out, mean_errors = {}, {}
    for name, traj in trajectories.items():
        out[name] = (traj.q_hat - state)[valid].pow(2).mean(0).tolist()
        eps_v, eps_q = model.prediction_errors(traj, batch["vision"], state)
        mean_errors[name] = {"proprio": float(eps_q[valid].mean()), "vision": float(eps_v[fresh].mean())}
    if store is not None:
        out["removed"] = {key: 1.0 - mean_errors["posteriors"][key] / mean_errors["open_loop"][key]
                          for key in ("proprio", "vision")}
    mean_state = state.clone()
    w = valid.float()[..., None]
    for eps in data.episodes:
        mean_state[:, eps] = ((state[:, eps] * w[:, eps]).sum(1, keepdim=True)
                              / w[:, eps].sum(1, keepdim=True).clamp_min(1))
    out["demo_spread"] = (mean_state - state)[valid].pow(2).mean(0).tolist()
    return out


def replay_error_regression(policy: PredVLAPolicy, data: TaskData, episodes: list[int]) -> dict:
    """Error regression on the given episodes' own observations, all at once as a batch.

    Returns per-step (time, batch) arrays: eps_v, eps_q, free energy of the newest step, prior-posterior gap
    per module, and the actions of error regression and of the open-loop chain (normalised).
    """
    model, cfg = policy.model, policy.config
    e = torch.as_tensor(episodes)
    batch = data.sequences.batch(e, torch.device("cpu"))
    steps = int(data.sequences.length[e].max())
    er = ErrorRegression(model)
    r = cfg.latent_dim
    records = {k: [] for k in ("eps_v", "eps_q", "free_energy", "gap", "action")}
    for t in range(steps):
        er.observe(batch["language"], batch["vision"][t], batch["state"][t])
        er.infer()
        with torch.no_grad():
            c_q = torch.stack(er.posteriors)
            traj = er.rollout(er.start_state, er.lang_term, c_q)
            er.state = traj.final
            eps_v, eps_q = model.prediction_errors(traj, torch.stack(er.vision), torch.stack(er.proprio))
            c_p = model.priors(traj)
            complexity = model.complexity(c_q[-1:], c_p[-1:], (cfg.er_complexity_weight,) * 4)[0]
            # The visual error counts on refresh steps only (Section 4.3): the newest step's weight is 0 or 1.
            w_v, w_q = er.vision_weight[-1], er.proprio_weight[-1]
            records["eps_v"].append(torch.where(w_v > 0, eps_v[-1], torch.full_like(eps_v[-1], float("nan"))))
            records["eps_q"].append(eps_q[-1])
            records["free_energy"].append(cfg.er_lambda_v * eps_v[-1] * w_v + cfg.er_lambda_q * eps_q[-1] * w_q
                                          + complexity)
            records["gap"].append((c_q[-1] - c_p[-1]).unflatten(-1, (4, r)).norm(dim=-1))
            records["action"].append(traj.final.a_hat)
    out = {k: torch.stack(v) for k, v in records.items()}
    out["open_loop_action"] = open_loop(policy, batch["language"], steps)
    out["demo_action"] = batch["action"][:steps]
    out["valid"] = batch["valid"][:steps]
    return out


def er_summary(replay: dict, data: TaskData) -> dict:
    """Action error of error regression and of open loop against the replayed demonstrations (raw units)."""
    valid = replay["valid"]
    demo = data.raw(replay["demo_action"])[valid]
    er = (data.raw(replay["action"])[valid] - demo).pow(2)
    ol = (data.raw(replay["open_loop_action"])[valid] - demo).pow(2)
    gap = replay["gap"][valid]
    return {
        "er_action_mse": float(er.mean()),
        "open_loop_action_mse": float(ol.mean()),
        "er_gripper_mse": float(er[:, -1].mean()),  # the last action dimension
        "open_loop_gripper_mse": float(ol[:, -1].mean()),
        "er_gap_per_module": {name: float(gap[:, m].mean()) for m, name in enumerate(MODULE_NAMES)},
        "er_eps_q": float(replay["eps_q"][valid].mean()),
        "er_eps_v": float(replay["eps_v"][valid].nanmean()),
    }


# Inference settings an offline replay may vary (Table 2's "Online error regression" rows and the A4/A5 weights).
ER_SETTINGS = {"er_window": int, "er_iterations": int, "er_lr": float, "er_complexity_weight": float,
               "er_lambda_v": float, "er_lambda_q": float}


def parse_er_variant(text: str) -> dict[str, int | float]:
    """`KEY=VALUE[,KEY=VALUE]` of `ER_SETTINGS` -> typed overrides; ValueError naming what is wrong."""
    overrides: dict[str, int | float] = {}
    for item in text.split(","):
        key, sep, value = item.strip().partition("=")
        if not sep or key not in ER_SETTINGS:
            raise ValueError(f"--er-variant {text!r}: expected KEY=VALUE[,KEY=VALUE] with KEY one of "
                             f"{', '.join(ER_SETTINGS)}, got {item.strip()!r}.")
        try:
            overrides[key] = ER_SETTINGS[key](value)
        except ValueError:
            raise ValueError(f"--er-variant {text!r}: {key} needs a {ER_SETTINGS[key].__name__}, "
                             f"got {value!r}.") from None
        if not overrides[key] > 0 and key in ("er_window", "er_iterations", "er_lr"):
            raise ValueError(f"--er-variant {text!r}: {key} must be positive (er_iterations=0 is the open loop "
                             "that every replay already reports).")
        if not overrides[key] >= 0:
            raise ValueError(f"--er-variant {text!r}: {key} must not be negative, got {value!r}.")
    return overrides


def replay_er_variant(policy: PredVLAPolicy, data: TaskData, episodes: list[int],
                      overrides: dict[str, int | float]) -> dict:
    """`er_summary` of error regression replayed with other inference settings; the config is restored after."""
    saved = {key: getattr(policy.config, key) for key in overrides}
    try:
        for key, value in overrides.items():
            setattr(policy.config, key, value)
        return {"settings": overrides, **er_summary(replay_error_regression(policy, data, episodes), data)}
    finally:
        for key, value in saved.items():
            setattr(policy.config, key, value)


def load_store(checkpoint: Path) -> Tensor | None:
    """The training posteriors saved beside a training checkpoint's weights, if any."""
    path = Path(checkpoint) / POSTERIOR_STORE_FILE
    return load_file(str(path))["latents"] if path.is_file() else None


def to_json(value):
    """Report values without tensors (those go to the plots)."""
    if isinstance(value, dict):
        return {k: to_json(v) for k, v in value.items() if not isinstance(v, Tensor)}
    if isinstance(value, list):
        return [to_json(v) for v in value]
    return value


def write_json(path: Path, report: dict) -> None:
    atomic_write_json(path, to_json(report))
