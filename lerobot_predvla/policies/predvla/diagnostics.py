"""What a researcher looks at first on a PredVLA checkpoint (`predvla inspect`).

Everything is computed offline against the training dataset's cached columns, without the simulator:

- open-loop actions (Section 3.5, n_itr = 0: every posterior at its prior) per task against the task's
  time-aligned mean demonstration, and against every other task's: does the instruction pick the behaviour?
- the language swap: the same open-loop chain driven by each other task's instruction, and how far the
  actions move; the drive of the language term W_lang l (Eq. 4) and of its differences between tasks;
- the training posteriors c_q (Eq. 10) per module: their size, their per-task means against the spread
  within a task, and their gap to the priors c_p (Eqs. 1-2) along the training rollout;
- the proprioceptive prediction error per dimension (Eq. 7), open loop and from the training posteriors;
- the forces on the network's weights (training checkpoints): each term of Eq. 10's gradient per weight, the
  gradient clipping's scale, and the weight decay against the clipped loss gradient, on a fixed batch and in
  Adam's own momentum (a weight whose decay outweighs its loss gradient is pulled toward zero by Adam);
- error regression replayed on one demonstration per task (its own observations, step by step as when
  acting): per-step prediction errors (Eq. 7), prior-posterior gap per module (Eq. 8), free energy (Eq. 9),
  and its actions against the demonstrated ones next to the open-loop chain's.
"""

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from lerobot.datasets.lerobot_dataset import LeRobotDatasetMetadata
from lerobot.utils.constants import ACTION, OPTIMIZER_STATE, TRAINING_STATE_DIR
from safetensors.torch import load_file
from torch import Tensor

from lerobot_predvla.policies.common.sequence_table import EpisodeSequences, read_columns
from lerobot_predvla.utils.io import atomic_write_json

from .configuration_predvla import ER_ADAM_STATES, ER_OPTIMIZERS, MODULE_NAMES
from .error_regression import ErrorRegression
from .modeling_predvla import PredVLAPolicy, refresh_mask, term_weights, training_terms
from .posterior_store import POSTERIOR_STORE_FILE


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
    refresh steps) that the posteriors remove, 1 - posteriors / open loop. `action_mse` (raw units) compares the
    decoded actions with the demonstrated ones: from the training posteriors it is what error regression would
    give were it to recover them exactly, `removed["action"]` its fraction of the open loop's.
    """
    model, seq = policy.model, data.sequences
    batch = seq.batch(torch.arange(seq.state.shape[0]), torch.device("cpu"))
    valid, state = batch["valid"], batch["state"]  # (L, E), (L, E, P)
    fresh = refresh_mask(valid, policy.config.visual_refresh_interval)
    lang_term = model.language_term(batch["language"])
    trajectories = {"open_loop": model.rollout(model.initial_state(valid.shape[1]), lang_term, steps=valid.shape[0])}
    if store is not None:
        trajectories["posteriors"] = model.rollout(model.initial_state(valid.shape[1]), lang_term,
                                                   store.transpose(0, 1))
    out, mean_errors = {"action_mse": {}}, {}
    demo_action = data.raw(batch["action"])[valid]
    for name, traj in trajectories.items():
        out[name] = (traj.q_hat - state)[valid].pow(2).mean(0).tolist()
        eps_v, eps_q = model.prediction_errors(traj, batch["vision"], state)
        out["action_mse"][name] = action_mse(data.raw(traj.a_hat)[valid], demo_action)
        mean_errors[name] = {"proprio": float(eps_q[valid].mean()), "vision": float(eps_v[fresh].mean()),
                             "action": out["action_mse"][name]}
    if store is not None:
        out["removed"] = {key: 1.0 - mean_errors["posteriors"][key] / mean_errors["open_loop"][key]
                          for key in ("proprio", "vision", "action")}
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


def gripper_events(action: Tensor, valid: Tensor) -> Tensor:
    """(batch, 2): the first step of each episode that closes the gripper (the last action dimension positive in raw
    units, LIBERO's close command) and the first step after it that opens it again; NaN where it never happens
    within the episode (`valid`, (time, batch))."""
    closed = (action[..., -1] > 0) & valid
    steps = torch.arange(len(action), dtype=torch.float)[:, None].expand_as(closed)
    never = torch.full_like(steps, float("inf"))
    close = torch.where(closed, steps, never).min(0).values
    released = ~closed & valid & (steps > close)
    release = torch.where(released, steps, never).min(0).values
    return torch.stack([close, release], dim=-1).nan_to_num(posinf=float("nan"))


def gripper_timing(replay: dict, data: TaskData, key: str) -> dict[str, float]:
    """How many steps `replay[key]`'s gripper closes and reopens after the replayed demonstrations' (mean signed
    difference: negative is early) and how far off on average (mean absolute difference), over the episodes where
    both happen; `missing`: episodes where the demonstration's event happens and this one's does not."""
    valid = replay["valid"]
    demo = gripper_events(data.raw(replay["demo_action"]), valid)
    mode = gripper_events(data.raw(replay[key]), valid)
    lead = mode - demo
    out = {}
    for i, event in enumerate(("close", "release")):
        both = ~lead[:, i].isnan()
        out[event] = float(lead[both, i].mean()) if both.any() else float("nan")
        out[f"{event}_abs"] = float(lead[both, i].abs().mean()) if both.any() else float("nan")
        out[f"{event}_missing"] = int((~demo[:, i].isnan() & mode[:, i].isnan()).sum())
    return out


def er_summary(replay: dict, data: TaskData) -> dict:
    """Action error of error regression and of open loop against the replayed demonstrations (raw units), and when
    each moves the gripper against the demonstrations (`gripper_timing`)."""
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
        "er_gripper_timing": gripper_timing(replay, data, "action"),
        "open_loop_gripper_timing": gripper_timing(replay, data, "open_loop_action"),
        "er_gap_per_module": {name: float(gap[:, m].mean()) for m, name in enumerate(MODULE_NAMES)},
        "er_eps_q": float(replay["eps_q"][valid].mean()),
        "er_eps_v": float(replay["eps_v"][valid].nanmean()),
    }


def gap_over_training(er: dict, posteriors: dict) -> dict[str, float]:
    """Error regression's mean prior-posterior gap per module as a multiple of the training posteriors' gap: far
    above 1, error regression puts the posteriors where the network never saw them."""
    return {name: er["er_gap_per_module"][name] / max(p["prior_gap"], 1e-12) for name, p in posteriors.items()}


# Inference settings an offline replay may vary (Table 2's "Online error regression" rows and the A4/A5 weights).
ER_SETTINGS = {"er_window": int, "er_iterations": int, "er_lr": float, "er_complexity_weight": float,
               "er_lambda_v": float, "er_lambda_q": float, "er_adam_state": str, "er_optimizer": str}
ER_CHOICES = {"er_adam_state": ER_ADAM_STATES, "er_optimizer": ER_OPTIMIZERS}  # the settings that name a choice


def parse_er_variant(text: str) -> dict[str, int | float | str]:
    """`KEY=VALUE[,KEY=VALUE]` of `ER_SETTINGS` -> typed overrides; ValueError naming what is wrong."""
    overrides: dict[str, int | float | str] = {}
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
        if key in ER_CHOICES:
            if value not in ER_CHOICES[key]:
                raise ValueError(f"--er-variant {text!r}: {key} must be one of {ER_CHOICES[key]}, got {value!r}.")
            continue
        if not overrides[key] > 0 and key in ("er_window", "er_iterations", "er_lr"):
            raise ValueError(f"--er-variant {text!r}: {key} must be positive (er_iterations=0 is the open loop "
                             "that every replay already reports).")
        if not overrides[key] >= 0:
            raise ValueError(f"--er-variant {text!r}: {key} must not be negative, got {value!r}.")
    return overrides


def replay_er_variant(policy: PredVLAPolicy, data: TaskData, episodes: list[int],
                      overrides: dict[str, int | float | str]) -> dict:
    """`er_summary` of error regression replayed with other inference settings; the config is restored after."""
    saved = {key: getattr(policy.config, key) for key in overrides}
    try:
        for key, value in overrides.items():
            setattr(policy.config, key, value)
        return {"settings": overrides, **er_summary(replay_error_regression(policy, data, episodes), data)}
    finally:
        for key, value in saved.items():
            setattr(policy.config, key, value)


# The weights that carry the task to the open-loop chain, by their symbols in Eqs. 1-4.
TOP_WEIGHTS = {"W_lang": "model.lang.weight", "W_pri T": "model.prior.0.weight", "W_pri V": "model.prior.1.weight",
               "W_pri A_top": "model.prior.2.weight", "W_pri A_bottom": "model.prior.3.weight",
               "U T": "model.latent.0.weight", "W_td V": "model.td.0.weight"}
FORCES_BATCH = 32  # Table 2's batch; a fixed draw of training episodes (seed 0), the same at every checkpoint


def forces_report(policy: PredVLAPolicy, data: TaskData, store: Tensor, weight_decay: float, grad_clip_norm: float,
                  momentum: dict[str, Tensor] | None = None) -> dict:
    """What trains each network weight at this checkpoint, on one batch of training episodes and their posteriors.

    Per parameter tensor: its norm; the norm of each Eq. 10 term's (weighted) gradient; `decay_over_loss`, the
    coupled L2 decay `weight_decay * p` that torch.optim.Adam adds to the gradient against the loss gradient after
    LeRobot's clipping to `grad_clip_norm` (above 1, Adam moves the weight mostly toward zero); and, given Adam's
    first moment (`momentum`, the checkpoint's exp_avg: the clipped loss gradient plus the decay, averaged over
    ~10 steps), `momentum_decay_over_loss`, the same ratio in what Adam actually steps on. Per module: each term's
    gradient on the posteriors c_q (which term moves them). Globally: the unclipped gradient norm and the clip scale.
    """
    cfg, model = policy.config, policy.model
    generator = torch.Generator().manual_seed(0)
    episodes = torch.randperm(store.shape[0], generator=generator)[:FORCES_BATCH]
    seq = data.sequences.batch(episodes, torch.device("cpu"))
    c_q = store[episodes].transpose(0, 1).clone().requires_grad_(True)
    params = dict(policy.named_parameters())
    was_training = policy.training
    policy.train()
    try:
        with torch.enable_grad():
            terms = training_terms(model, cfg, seq, c_q, model.language_term(seq["language"]))
            grads = {}
            for name, weight in term_weights(cfg).items():
                g = torch.autograd.grad(weight * terms[name], [*params.values(), c_q], retain_graph=True,
                                        allow_unused=True)
                grads[name] = [torch.zeros_like(x) if gi is None else gi for gi, x in zip(g, [*params.values(), c_q],
                                                                                          strict=True)]
    finally:
        policy.train(was_training)
    n = len(params)
    total = [sum(grads[k][i] for k in grads) for i in range(n)]
    total_norm = float(torch.stack([g.norm() for g in total]).norm())
    clip_scale = min(1.0, grad_clip_norm / (total_norm + 1e-6)) if grad_clip_norm > 0 else 1.0
    weights = {}
    for i, (name, p) in enumerate(params.items()):
        norm = float(p.detach().norm())
        decay = weight_decay * norm
        row = {"norm": norm,
               "term_grad_norm": {k: float(grads[k][i].norm()) for k in grads},
               "decay_over_loss": decay / max(clip_scale * float(total[i].norm()), 1e-12)}
        if momentum is not None and name in momentum:
            loss_momentum = momentum[name].float() - weight_decay * p.detach()
            row["momentum_decay_over_loss"] = decay / max(float(loss_momentum.norm()), 1e-12)
        weights[name] = row
    r = cfg.latent_dim
    posterior = {m: {k: float(grads[k][n].unflatten(-1, (4, r))[..., j, :].norm()) for k in grads}
                 for j, m in enumerate(MODULE_NAMES)}
    return {"episodes": episodes.tolist(), "terms": {k: float(v.detach()) for k, v in terms.items()},
            "grad_norm": total_norm, "grad_clip_norm": grad_clip_norm, "clip_scale": clip_scale,
            "weight_decay": weight_decay, "weights": weights, "posterior_term_grad_norm": posterior}


def optimizer_settings(checkpoint: Path) -> tuple[float, float] | None:
    """(weight_decay, grad_clip_norm) of the training that wrote a checkpoint, from its train_config.json."""
    path = Path(checkpoint) / "train_config.json"
    if not path.is_file():
        return None
    optimizer = json.loads(path.read_text()).get("optimizer") or {}
    return float(optimizer.get("weight_decay", 0.0)), float(optimizer.get("grad_clip_norm", 0.0))


def load_momentum(checkpoint: Path, policy: PredVLAPolicy) -> dict[str, Tensor] | None:
    """Adam's first moments of a training checkpoint by parameter name (LeRobot saves them by parameter index,
    in `policy.parameters()` order), or None where the checkpoint has no optimizer state."""
    path = Path(checkpoint).parent / TRAINING_STATE_DIR / OPTIMIZER_STATE
    if not path.is_file():
        return None
    state = load_file(str(path))
    out = {}
    for i, (name, p) in enumerate(policy.named_parameters()):
        m = state.get(f"state/{i}/exp_avg")
        if m is None or m.shape != p.shape:
            return None  # not this policy's optimizer layout
        out[name] = m
    return out


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
