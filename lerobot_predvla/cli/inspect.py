"""`predvla inspect`: diagnostics of a PredVLA checkpoint against its training dataset, with plots.

CHECKPOINT is a `pretrained_model` directory, or a `lerobot-train` output directory: then every saved
checkpoint is inspected (cheap numbers, drawn over training steps) and the last one in full. Writes
`inspect.json` and figures to --out:

- open_loop_vs_demos.png: open-loop actions per task against the task's mean demonstration (+- 1 std),
  and error regression's actions replayed on one demonstration of the task;
- errors_over_episode.png: per-step prediction errors, complexity and free energy during error regression;
- prior_posterior_gap.png: the posterior-prior gap per module, training posteriors and error regression;
- language_swap.png: open-loop actions under each instruction against each task's mean demonstration;
- proprio_error_per_dim.png: the proprioceptive prediction error per dimension, open loop and from the training
  posteriors, beside the demonstrations' spread around their task's mean;
- training_curves.png (several checkpoints): the same numbers over training, with the norms of the weights that
  carry the task to the open-loop chain (W_lang, the priors' W_pri, U^T, W_td) and their weight decay against the
  clipped loss gradient in Adam's momentum (training checkpoints: `forces` in inspect.json).

`--er-variant KEY=VALUE[,KEY=VALUE]` (repeatable) replays error regression once more per variant with other
inference settings on the same demonstrations and prints a table beside Table 2's settings: which settings bring
the actions closer to the demonstrated ones, without the simulator.
"""

import argparse
import json
import sys
from pathlib import Path

from lerobot.utils.constants import CHECKPOINTS_DIR
from lerobot.utils.constants import PRETRAINED_MODEL_DIR as PRETRAINED_DIR
from tqdm import tqdm

from lerobot_predvla.policies.predvla import diagnostics as dx
from lerobot_predvla.policies.predvla.configuration_predvla import MODULE_NAMES
from lerobot_predvla.policies.predvla.diagnostics import TOP_WEIGHTS
from lerobot_predvla.policies.predvla.modeling_predvla import PredVLAPolicy
from lerobot_predvla.utils.checkpoints import find_pretrained
from lerobot_predvla.utils.io import atomic_save_figure

# Error regression's prior-posterior gap, as a multiple of the training posteriors', above which the summary warns.
GAP_WARNING = 3.0


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("inspect", help="diagnostics and plots of a PredVLA checkpoint (no simulator)",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("checkpoint", type=Path, help="a pretrained_model directory or a lerobot-train output directory")
    p.add_argument("--dataset-root", type=Path, default=None,
                   help="training dataset (default: dataset.root of the checkpoint's train_config.json)")
    p.add_argument("--out", type=Path, default=None, help="output directory (default: CHECKPOINT/inspect)")
    p.add_argument("--no-er", action="store_true", help="skip the error-regression replay (the slow part)")
    p.add_argument("--er-variant", action="append", default=[], metavar="KEY=VALUE[,KEY=VALUE]",
                   help="also replay error regression with these inference settings, one variant per flag "
                        "(keys: er_window, er_iterations, er_lr, er_adam_state (fresh or carried), "
                        "er_optimizer (adam or gd), er_complexity_weight, er_lambda_v, er_lambda_q)")
    p.add_argument("--every", type=int, default=None, metavar="N",
                   help="with a lerobot-train output directory: inspect only the checkpoints whose step is a multiple "
                        "of N, and the last one (default: every checkpoint)")
    p.set_defaults(func=run)


def find_checkpoints(path: Path, every: int | None = None) -> list[tuple[int | None, Path]]:
    """(training step, pretrained_model directory) pairs, oldest first; with `every`, only steps that are a
    multiple of it, and the last."""
    pretrained = find_pretrained(path)
    if pretrained is not None:
        return [(None, pretrained)]
    found = sorted((int(d.name), d / PRETRAINED_DIR) for d in (path / CHECKPOINTS_DIR).glob("*")
                   if d.name.isdigit() and (d / PRETRAINED_DIR / "config.json").is_file())
    if not found:
        raise ValueError(f"{path}: no PredVLA checkpoint (expected config.json, {PRETRAINED_DIR}/ or "
                         f"{CHECKPOINTS_DIR}/<step>/{PRETRAINED_DIR}/).")
    if every is None:
        return found
    if every < 1:
        raise ValueError(f"--every must be >= 1, got {every}.")
    return [(step, d) for step, d in found if step % every == 0 or (step, d) == found[-1]]


def dataset_root(checkpoint: Path) -> Path:
    train_config = checkpoint / "train_config.json"
    if not train_config.is_file():
        raise ValueError(f"{checkpoint}: no train_config.json to read the training dataset from; pass --dataset-root.")
    root = json.loads(train_config.read_text()).get("dataset", {}).get("root")
    if not root:
        raise ValueError(f"{train_config}: dataset.root is empty; pass --dataset-root.")
    return Path(root)


def run(args: argparse.Namespace) -> int:
    try:
        variants = [dx.parse_er_variant(text) for text in args.er_variant]
        if variants and args.no_er:
            raise ValueError("--er-variant replays error regression; it cannot go with --no-er.")
        checkpoints = find_checkpoints(args.checkpoint, args.every)
        root = args.dataset_root or dataset_root(checkpoints[-1][1])
        if not (root / "meta" / "info.json").is_file():
            raise ValueError(f"{root}: not a LeRobot dataset (meta/info.json missing).")
    except ValueError as err:
        print(f"predvla inspect: error: {err}", file=sys.stderr)
        return 2
    out = args.out or (args.checkpoint / "inspect")
    out.mkdir(parents=True, exist_ok=True)
    history, data = [], None
    for step, path in tqdm(checkpoints, desc="checkpoints", unit="ckpt"):
        policy = PredVLAPolicy.from_pretrained(path).eval()
        data = data or dx.TaskData.load(root, policy)
        report = {"step": step, "checkpoint": str(path), "language": dx.language_report(policy, data)}
        store = dx.load_store(path)
        if store is not None:
            report["posteriors"] = dx.posterior_report(policy, data, store)
        report["proprio_error_per_dim"] = dx.proprio_report(policy, data, store)
        settings = dx.optimizer_settings(path)
        if store is not None and settings is not None:
            report["forces"] = dx.forces_report(policy, data, store, *settings, dx.load_momentum(path, policy))
        history.append(report)
    last = history[-1]
    replay = None
    if not args.no_er and policy.config.er_iterations > 0:
        episodes = [eps[0] for eps in data.episodes]
        replay = dx.replay_error_regression(policy, data, episodes)
        last["error_regression"] = dx.er_summary(replay, data)
        last["error_regression_variants"] = [
            dx.replay_er_variant(policy, data, episodes, overrides)
            for overrides in tqdm(variants, desc="error-regression variants", unit="variant")]
        if "posteriors" in last:
            for er in (last["error_regression"], *last["error_regression_variants"]):
                er["er_gap_over_training"] = dx.gap_over_training(er, last["posteriors"])
    last["tasks"] = data.names
    plot_all(out, data, history, replay)
    dx.write_json(out / "inspect.json", {"dataset_root": str(root), "history": history})
    print_summary(last)
    print(f"wrote {out / 'inspect.json'} and figures to {out}")
    return 0


def print_summary(report: dict) -> None:
    lang = report["language"]
    print(f"\nopen loop vs mean demonstrations (raw action MSE), {len(report['tasks'])} tasks:")
    print(f"{'task':>4}  {'own':>8}  {'nearest other':>13}  {'demo spread':>11}  name (task index of the dataset)")
    for i, name in enumerate(report["tasks"]):
        other = lang["open_loop_mse_nearest_other_task"][i]
        print(f"{i:>4}  {lang['open_loop_mse_own_task'][i]:>8.4f}  {other if other is None else f'{other:>13.4f}'}"
              f"  {lang['demo_spread_mse'][i]:>11.4f}  {name}")
    print(f"open loop closest to its own task's mean demonstration: {lang['open_loop_picks_own_task']:.0%}")
    print(f"language swap: actions move {lang['mean_language_swap_mse']:.4f} (mean demos differ by "
          f"{lang['mean_demo_gap']:.4f}); |W_lang l| {lang['language_drive_norm']:.3f}, "
          f"|W_lang (l_i - l_j)| {lang['language_difference_drive_norm']:.3f}")
    for name, p in report.get("posteriors", {}).items():
        print(f"posteriors {name:>8}: |c_q| {p['mean_norm']:.3f}, per-task means {p['between_task_mean_distance']:.3f}"
              f" apart vs {p['within_task_spread']:.3f} within a task, |c_q - c_p| {p['prior_gap']:.3f}")
    if "forces" in report:
        f = report["forces"]
        print(f"gradient norm {f['grad_norm']:.1f}, clipped to {f['grad_clip_norm']:g} (scale {f['clip_scale']:.3f});"
              f" weight decay {f['weight_decay']:g} against the clipped loss gradient (batch / Adam's momentum):")
        print("  " + ", ".join(f"{label} {f['weights'][name]['decay_over_loss']:.2f}"
                               f"/{f['weights'][name].get('momentum_decay_over_loss', float('nan')):.2f}"
                               for label, name in TOP_WEIGHTS.items()))
    q = report["proprio_error_per_dim"]
    if "removed" in q:
        print(f"the training posteriors remove {q['removed']['proprio']:.0%} of the open loop's proprioceptive error, "
              f"{q['removed']['vision']:.0%} of its visual error and {q['removed']['action']:.0%} of its action error "
              f"(action MSE {q['action_mse']['posteriors']:.4f}, open loop {q['action_mse']['open_loop']:.4f})")
    for name in ("open_loop", "posteriors", "demo_spread"):
        if name in q:
            print(f"proprioceptive error per dimension, {name.replace('_', ' ')}: "
                  + " ".join(f"{v:.1e}" for v in q[name]) + f" (mean {sum(q[name]) / len(q[name]):.4f})")
    if "error_regression" in report:
        er = report["error_regression"]
        print(f"error regression replayed on one demonstration per task: action MSE {er['er_action_mse']:.4f} "
              f"(open loop {er['open_loop_action_mse']:.4f}); eps_q {er['er_eps_q']:.4g}, eps_v {er['er_eps_v']:.4g}")
        timing, open_loop = er["er_gripper_timing"], er["open_loop_gripper_timing"]
        print(f"the gripper closes {timing['close']:+.1f} steps and reopens {timing['release']:+.1f} steps after the "
              f"demonstrations' (open loop {open_loop['close']:+.1f}, {open_loop['release']:+.1f}; negative: early)")
        ratio = er.get("er_gap_over_training", {})
        if ratio and max(ratio.values()) > GAP_WARNING:
            module = max(ratio, key=ratio.get)
            print(f"error regression puts the posteriors up to {ratio[module]:.0f}x further from their priors than the "
                  f"training posteriors ({module}), where the action head was never trained: Adam's first iteration "
                  f"moves every coordinate by er_lr; compare a smaller one or Adam's moments carried over the "
                  f"window (--er-variant er_lr=..., --er-variant er_adam_state=carried)")
        if report.get("error_regression_variants"):
            print_er_variants(er, report["error_regression_variants"])


def print_er_variants(er: dict, variants: list[dict]) -> None:
    """The replayed variants beside the checkpoint's own settings (raw action MSE against the demonstrations, and
    the steps by which the gripper closes and reopens after the demonstrations': negative is early)."""
    print(f"\n{'error regression settings':<40} {'action MSE':>10} {'gripper MSE':>11} {'close':>6} {'release':>7} "
          + " ".join(f"{'gap ' + m:>12}" for m in MODULE_NAMES))
    rows = [("checkpoint's own", er), *((",".join(f"{k}={v}" for k, v in r["settings"].items()), r) for r in variants),
            ("exact open loop", {"er_action_mse": er["open_loop_action_mse"],
                                 "er_gripper_mse": er["open_loop_gripper_mse"],
                                 "er_gripper_timing": er["open_loop_gripper_timing"]})]
    for name, r in rows:
        gaps, timing = r.get("er_gap_per_module", {}), r["er_gripper_timing"]
        print(f"{name:<40} {r['er_action_mse']:>10.4f} {r['er_gripper_mse']:>11.4f} {timing['close']:>+6.1f} "
              f"{timing['release']:>+7.1f} "
              + " ".join(f"{gaps[m]:>12.3f}" if m in gaps else f"{'':>12}" for m in MODULE_NAMES))


def plot_all(out: Path, data, history: list[dict], replay: dict | None) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    def save(fig, name: str) -> None:
        fig.tight_layout()
        atomic_save_figure(fig, out / name, dpi=100)
        plt.close(fig)

    last = history[-1]
    tasks = len(data.names)
    actions = data.raw(last["language"]["open_loop_actions"])
    means = data.raw(data.mean_action)
    seq = data.sequences
    dims = actions.shape[-1]
    fig, axes = plt.subplots(tasks, dims, figsize=(2.2 * dims, 1.6 * tasks + 0.6), squeeze=False, sharex=True)
    for t in range(tasks):
        horizon = int(seq.length[data.episodes[t]].max())
        demos = data.raw(seq.action[data.episodes[t], :horizon])
        for k in range(dims):
            ax = axes[t, k]
            std = demos[..., k].std(0)
            ax.fill_between(range(horizon), means[t, :horizon, k] - std, means[t, :horizon, k] + std,
                            color="0.8", lw=0)
            ax.plot(means[t, :horizon, k], "k", lw=1, label="mean demonstration")
            ax.plot(actions[t, :horizon, k], "C0", lw=1, label="open loop")
            if replay is not None:
                n = int(replay["valid"][:, t].sum())
                ax.plot(data.raw(replay["action"][:n, t])[:, k], "C1", lw=0.8, label="error regression (replay)")
            if t == 0:
                ax.set_title(f"action {k}", fontsize=8)
            if k == 0:
                ax.set_ylabel(f"task {t}", fontsize=8)
            ax.tick_params(labelsize=6)
    axes[0, 0].legend(fontsize=6, loc="best")
    save(fig, "open_loop_vs_demos.png")

    vs_demo, swap = last["language"]["open_loop_vs_mean_demos"], last["language"]["language_swap_mse"]
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2))
    for ax, matrix, title in ((axes[0], vs_demo, "open loop under instruction i vs mean demo of task j"),
                              (axes[1], swap, "open loop under instruction i vs under instruction j")):
        image = ax.imshow(matrix, cmap="viridis")
        ax.set(xlabel="j", ylabel="i", title=title)
        ax.title.set_fontsize(8)
        fig.colorbar(image, ax=ax, fraction=0.046)
    save(fig, "language_swap.png")

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.5))
    width = 0.8 / len(MODULE_NAMES)
    if "posteriors" in last:
        gaps = [last["posteriors"][m]["prior_gap"] for m in MODULE_NAMES]
        norms = [last["posteriors"][m]["mean_norm"] for m in MODULE_NAMES]
        axes[0].bar([i - width / 2 for i in range(4)], gaps, width, label="|c_q - c_p|")
        axes[0].bar([i + width / 2 for i in range(4)], norms, width, label="|c_q|")
        axes[0].legend(fontsize=7)
    axes[0].set(xticks=range(4), xticklabels=MODULE_NAMES, title="training posteriors (mean per step)")
    if replay is not None:
        for m, name in enumerate(MODULE_NAMES):
            axes[1].plot(replay["gap"][:, :, m].mean(1), label=name)
        axes[1].legend(fontsize=7)
    axes[1].set(xlabel="control step", title="error regression: |c_q - c_p| at the newest step")
    for ax in axes:
        ax.title.set_fontsize(9)
    save(fig, "prior_posterior_gap.png")

    q = last["proprio_error_per_dim"]
    shown = [name for name in ("open_loop", "posteriors", "demo_spread") if name in q]
    fig, ax = plt.subplots(figsize=(1 + 0.7 * len(q["open_loop"]), 3.2))
    width = 0.8 / len(shown)
    for i, name in enumerate(shown):
        ax.bar([k + (i - (len(shown) - 1) / 2) * width for k in range(len(q[name]))], q[name], width,
               label=name.replace("_", " "))
    ax.set(xticks=range(len(q["open_loop"])), xlabel="proprioceptive dimension", yscale="log",
           title="proprioceptive prediction error per dimension\n(Eq. 7, squared error in the preprocessed units, "
                 "training episodes)")
    ax.title.set_fontsize(9)
    ax.legend(fontsize=7)
    save(fig, "proprio_error_per_dim.png")

    if replay is not None:
        fig, axes = plt.subplots(1, 4, figsize=(15, 3.2))
        for ax, key in zip(axes, ("eps_v", "eps_q", "free_energy"), strict=False):
            for t in range(replay[key].shape[1]):
                n = int(replay["valid"][:, t].sum())
                y = replay[key][:n, t]
                ax.plot(range(n)[:: 4 if key == "eps_v" else 1], y[:: 4 if key == "eps_v" else 1], lw=0.8)
            ax.set(title=key, xlabel="control step", yscale="log")
        err = (data.raw(replay["action"]) - data.raw(replay["demo_action"])).pow(2).mean(-1)
        ol = (data.raw(replay["open_loop_action"]) - data.raw(replay["demo_action"])).pow(2).mean(-1)
        axes[3].plot(err.mean(1), label="error regression")
        axes[3].plot(ol.mean(1), label="open loop")
        axes[3].set(title="action MSE vs the replayed demonstration", xlabel="control step", yscale="log")
        axes[3].legend(fontsize=7)
        for ax in axes:
            ax.title.set_fontsize(9)
        save(fig, "errors_over_episode.png")

    steps = [h["step"] for h in history]
    if len(history) > 1 and None not in steps and tasks > 1:
        save(training_curves(plt, steps, history, tasks), "training_curves.png")


def training_curves(plt, steps: list[int], history: list[dict], tasks: int):
    """The mechanism over training, one panel per question: does the instruction pick the task's behaviour, do
    the posteriors explain what each demonstration adds, how far are priors from posteriors."""
    fig, axes = plt.subplots(2, 4, figsize=(18, 6.4))
    axes = axes.flatten()
    lang = [h["language"] for h in history]
    axes[0].plot(steps, [100 * x["open_loop_picks_own_task"] for x in lang], "o-")
    axes[0].axhline(100 / tasks, color="0.6", ls="--", label="chance")
    axes[0].set(title="open loop closest to its own task's mean demonstration (% of tasks)", ylim=(0, 105))
    axes[1].plot(steps, [sum(x["open_loop_mse_own_task"]) / tasks for x in lang], label="own task")
    axes[1].plot(steps, [sum(x["open_loop_mse_nearest_other_task"]) / tasks for x in lang],
                 label="nearest other task")
    axes[1].set(title="open loop vs mean demonstrations (action MSE)", yscale="log")
    axes[2].plot(steps, [x["mean_language_swap_mse"] for x in lang], label="language swap (action MSE)")
    axes[2].plot(steps, [x["mean_demo_gap"] for x in lang], label="between tasks' mean demonstrations")
    axes[2].set(title="instruction swap: how far the open-loop actions move")
    removed = [h["proprio_error_per_dim"].get("removed") for h in history]
    if all(r is not None for r in removed):
        for key in ("proprio", "vision", "action"):
            if all(key in r for r in removed):  # histories written before the action error was reported lack it
                axes[3].plot(steps, [100 * r[key] for r in removed], "o-", label=key)
    axes[3].set(title="open-loop prediction error the training posteriors remove (%)")
    if all("posteriors" in h for h in history):
        for name in MODULE_NAMES:
            axes[4].plot(steps, [h["posteriors"][name]["prior_gap"] for h in history], label=name)
    axes[4].set(title="training |c_q - c_p| per module")
    axes[5].plot(steps, [x["language_difference_drive_norm"] for x in lang], label="|W_lang (l_i - l_j)|")
    axes[5].plot(steps, [x["language_drive_norm"] for x in lang], label="|W_lang l|")
    axes[5].set(title="language drive of T (Eq. 4)")
    if all("forces" in h for h in history):
        for label, name in TOP_WEIGHTS.items():
            line, = axes[6].plot(steps, [h["forces"]["weights"][name]["norm"] for h in history], label=label)
            axes[7].plot(steps, [h["forces"]["weights"][name].get("momentum_decay_over_loss", float("nan"))
                                 for h in history], color=line.get_color(), label=label)
        axes[7].axhline(1.0, color="0.6", ls="--")
    axes[6].set(title="weight norms of the top of the hierarchy")
    axes[7].set(title="Adam momentum: weight decay / clipped loss gradient (>1: pulled to 0)", yscale="log")
    for ax in axes:
        ax.set_xlabel("training step")
        ax.legend(fontsize=7)
        ax.title.set_fontsize(8)
    return fig
