"""Error regression traced while acting (`predvla trace`), step by step and episode by episode.

Per control step of every episode: the action returned, the action of the prior chain at that step
(`ErrorRegression.prior_action`: the mode of the GMM head from the state before the step's inference), and how far
the step's `er_iterations` Adam iterations (Section 3.5) moved the posteriors c_q of each module (T, V, A_top,
A_bottom): the Euclidean norm of the change of the newest step's posterior (it starts at its prior, Eqs. 1-2) and
the mean of that norm over the window; and what the moves answered: the newest step's prediction errors eps_v, eps_q
(Eq. 7) at the window's posteriors before the iterations (the deviation just observed: the newest posterior is
still its prior) and after them, with whether the step's frame was a fresh one (`vision_weight`). In exact open
loop (`er_iterations` = 0) there are no moves and no errors (no observation is read).

`correlations` and `plot_corrections` put the moves against the observed deviation, per module, over every traced
step: which module error regression moves when the observation departs from the prediction.
"""

from pathlib import Path

import torch
from scipy.stats import spearmanr
from torch import Tensor

from lerobot_predvla.utils.io import atomic_save_figure

from .configuration_predvla import MODULE_NAMES
from .error_regression import ErrorRegression
from .predictive_model import Trajectory

TRACED_KEYS = ("action", "prior_action", "move_newest", "move_window", "error_before", "error_after",
               "vision_weight")
ERROR_NAMES = ("vision", "proprio")  # the two prediction errors of Eq. 7, in the order `newest_errors` gives them


def newest_errors(er: ErrorRegression, traj: Trajectory) -> list[list[float]]:
    """[eps_v, eps_q] (Eq. 7) of the window's newest step per environment, on the window regenerated as `traj`."""
    with torch.no_grad():
        eps_v, eps_q = er.model.prediction_errors(traj, torch.stack(er.vision), torch.stack(er.proprio))
    return torch.stack([eps_v[-1], eps_q[-1]], dim=-1).tolist()


class TraceRecorder:
    """`ErrorRegression.tracer` that keeps every step of every batch of episodes (a batch starts at step 1)."""

    def __init__(self) -> None:
        self.batches: list[list[dict]] = []

    def __call__(self, er: ErrorRegression, before: Tensor | None, action: Tensor) -> None:
        if er.step_index == 1 or not self.batches:
            self.batches.append([])
        record = {"step": er.step_index, "action": action.tolist(), "prior_action": er.prior_action.tolist()}
        if before is not None:
            change = torch.stack(er.posteriors) - before  # (window, batch, modules x latent_dim)
            move = change.unflatten(-1, (len(MODULE_NAMES), -1)).norm(dim=-1)  # (window, batch, modules)
            record["move_newest"] = move[-1].tolist()
            record["move_window"] = move.mean(0).tolist()
            with torch.no_grad():
                window_before = er.rollout(er.start_state, er.lang_term, before)
            record["error_before"] = newest_errors(er, window_before)
            record["error_after"] = newest_errors(er, er.trajectory)  # the window `act` regenerated
            record["vision_weight"] = er.vision_weight[-1].tolist()
        self.batches[-1].append(record)

    def episodes(self) -> list[dict]:
        """One dict of per-step lists per episode, batch by batch, in the order lerobot-eval runs them."""
        out = []
        for steps in self.batches:
            for i in range(len(steps[0]["action"])):
                episode = {"steps": [s["step"] for s in steps]}
                for key in TRACED_KEYS:
                    if key in steps[0]:
                        episode[key] = [s[key][i] for s in steps]
                out.append(episode)
        return out


def plot_traces(traces: dict[str, dict], episode: int, path: Path) -> None:
    """The last action dimension (LIBERO: the gripper, +1 closes) and the newest step's move per module, of
    episode `episode` of each labelled trace, one figure."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1 + len(MODULE_NAMES), 1, figsize=(9, 9), sharex=True)
    for label, trace in traces.items():
        ep = trace["episodes"][episode]
        (line,) = axes[0].plot(ep["steps"], [a[-1] for a in ep["action"]], label=label)
        if "move_newest" in ep:
            for k, ax in enumerate(axes[1:]):
                ax.plot(ep["steps"], [m[k] for m in ep["move_newest"]], color=line.get_color(), label=label)
    axes[0].set_ylabel("last action dim.\n(LIBERO: gripper)")
    axes[0].legend(fontsize=8)
    for name, ax in zip(MODULE_NAMES, axes[1:], strict=True):
        ax.set_ylabel(f"move of c_q\n{name}")
    axes[-1].set_xlabel("control step")
    fig.suptitle(f"episode {episode}: action and posterior moves per step of error regression")
    fig.tight_layout()
    atomic_save_figure(fig, path, dpi=90)
    plt.close(fig)


def correction_points(episodes: list[dict]) -> dict[str, tuple[list[float], list[float], list[list[float]]]]:
    """Per prediction error ("vision": fresh frames only, "proprio"), over every traced step of all episodes: its
    value before the step's iterations, its value after them, and the newest posterior's move per module."""
    points: dict[str, tuple[list[float], list[float], list[list[float]]]] = {name: ([], [], []) for name in ERROR_NAMES}
    for ep in episodes:
        if "error_before" not in ep:
            continue
        for before, after, moves, weight in zip(ep["error_before"], ep["error_after"], ep["move_newest"],
                                                ep["vision_weight"], strict=True):
            for k, name in enumerate(ERROR_NAMES):
                if name == "vision" and weight == 0:
                    continue  # a stale frame: its error does not enter the free energy
                points[name][0].append(before[k])
                points[name][1].append(after[k])
                points[name][2].append(moves)
    return points


def correlations(episodes: list[dict]) -> dict[str, dict[str, float | None]]:
    """Spearman's rank correlation of each module's move with each prediction error observed before the step
    (None with fewer than three steps or a constant series), and the median ratio of each error after the
    iterations to before them (`median_after_over_before`: {error name: ratio})."""
    out: dict[str, dict[str, float | None]] = {}
    medians: dict[str, float | None] = {}
    for name, (errors, after, moves) in correction_points(episodes).items():
        row: dict[str, float | None] = {}
        for k, module in enumerate(MODULE_NAMES):
            series = [m[k] for m in moves]
            defined = len(errors) >= 3 and len(set(errors)) > 1 and len(set(series)) > 1
            row[module] = round(float(spearmanr(errors, series).statistic), 4) if defined else None
        out[name] = row
        ratios = sorted(a / b for b, a in zip(errors, after, strict=True) if b > 0)
        medians[name] = round(ratios[len(ratios) // 2], 4) if ratios else None
    return {**out, "median_after_over_before": medians}


def plot_corrections(episodes: list[dict], succeeded: list[bool] | None, path: Path, title: str) -> None:
    """One panel per module and prediction error: the newest posterior's move at each traced step against the
    error observed before the step's iterations, log-log; steps of succeeded and failed episodes apart when
    `succeeded` (one flag per episode) is given."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups = {"all episodes": episodes} if succeeded is None else {
        "succeeded": [ep for ep, ok in zip(episodes, succeeded, strict=False) if ok],
        "failed": [ep for ep, ok in zip(episodes, succeeded, strict=False) if not ok]}
    fig, axes = plt.subplots(len(ERROR_NAMES), len(MODULE_NAMES), figsize=(12, 5.5), squeeze=False)
    for label, group in groups.items():
        points = correction_points(group)
        for row, name in enumerate(ERROR_NAMES):
            errors, _, moves = points[name]
            for k, ax in enumerate(axes[row]):
                ax.scatter(errors, [m[k] for m in moves], s=3, alpha=0.3, label=label)
    for row, name in enumerate(ERROR_NAMES):
        for k, (module, ax) in enumerate(zip(MODULE_NAMES, axes[row], strict=True)):
            ax.set_xscale("log")
            ax.set_yscale("symlog", linthresh=1e-3)
            ax.set_xlabel(f"eps_{name[0]} before the step")
            if k == 0:
                ax.set_ylabel("move of the newest c_q")
            ax.set_title(f"{module} against eps_{name[0]}", fontsize=9)
    axes[0][0].legend(fontsize=8, markerscale=3)
    fig.suptitle(title)
    fig.tight_layout()
    atomic_save_figure(fig, path, dpi=90)
    plt.close(fig)
