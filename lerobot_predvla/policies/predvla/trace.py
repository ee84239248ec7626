"""Error regression traced while acting (`predvla trace`), step by step and episode by episode.

Per control step of every episode: the action returned, the action of the prior chain at that step
(`ErrorRegression.prior_action`: the mode of the GMM head from the state before the step's inference), and how far
the step's `er_iterations` Adam iterations (Section 3.5) moved the posteriors c_q of each module (T, V, A_top,
A_bottom): the Euclidean norm of the change of the newest step's posterior (it starts at its prior, Eqs. 1-2) and
the mean of that norm over the window. In exact open loop (`er_iterations` = 0) there are no moves.
"""

from pathlib import Path

import torch
from torch import Tensor

from lerobot_predvla.utils.io import atomic_save_figure

from .configuration_predvla import MODULE_NAMES
from .error_regression import ErrorRegression


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
        self.batches[-1].append(record)

    def episodes(self) -> list[dict]:
        """One dict of per-step lists per episode, batch by batch, in the order lerobot-eval runs them."""
        out = []
        for steps in self.batches:
            for i in range(len(steps[0]["action"])):
                episode = {"steps": [s["step"] for s in steps]}
                for key in ("action", "prior_action", "move_newest", "move_window"):
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
