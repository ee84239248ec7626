"""Where PredVLA's exact open loop leaves the demonstrations (`python -m research.divergence`): the measurement.

In the simulator: each chosen demonstration's own first MuJoCo state (and its fixture poses, from the scene XML it
saved) is set, and three action sequences are run from it, physics only:

- `replay`: the demonstration's own actions (the simulator's reproducibility: the floor of every distance below);
- `open_loop`: PredVLA's exact open-loop actions (`er_iterations=0`: every posterior at its prior, so the actions
  depend on the instruction alone), unnormalised by the checkpoint's postprocessor, up to the step cap (stopped at
  success, as `lerobot-eval` does);
- `open_loop_demo_rotation`: the same open-loop actions with their three rotation commands replaced by the
  demonstration's own (zero past its end): a counterfactual, how much of the open loop's failure its orientation
  carries;
- `blind_plan`: another demonstration's actions of the same task (the next one in the file), then idle steps up to
  the cap: what one plan replayed with no observation does from this start (the blind-replay reference).

Per step each rollout's end-effector position, joint angles and gripper are compared with the demonstration's
own recorded trajectory; the demonstration's phases (approach, grasp, lift, carry/place, release) come from its
gripper command and end-effector height.

Offline (no simulator): the open loop's actions against every demonstration of the task, per step, against the
task's time-aligned mean demonstration and against the demonstrations' spread (their envelope, min to max, and how
far each lies from the mean). The checkpoint holds no training posteriors, so the rollout driven by them (the
prior chain's one-step, training-mode error) cannot be measured here.

The command's run over tasks, its figures and its summary tables: report.py (`python -m research.divergence`).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path
from xml.etree import ElementTree

import h5py
import numpy as np
import torch

from lerobot_predvla.frontend.artefact import FrontendArtefact
from lerobot_predvla.frontend.language import LanguageEncoder
from lerobot_predvla.policies.predvla.diagnostics import open_loop
from lerobot_predvla.policies.predvla.modeling_predvla import PredVLAPolicy
from lerobot_predvla.sims.libero.env import fixture_poses, make_env, set_fixture_poses, task_spec
from lerobot_predvla.sims.libero.rollout import IDLE
from research.postprocessor import load_postprocessor

PHASES = ("approach", "grasp", "lift", "carry/place", "release")
SEPARATION_THRESHOLDS_M = (0.01, 0.02, 0.05, 0.10)
LIFT_RISE_M = 0.01  # the lift starts when the end effector is this far above where the gripper closed
TOP_MARGIN_M = 0.01  # the lift ends within this distance of the highest point before release
ENVELOPE_MIN_DEMOS = 0.5  # envelope and mean demonstration only where at least this fraction of demos still runs
EXIT_RUN = 3  # consecutive steps outside the envelope that count as leaving it
ENVELOPE_MARGIN = 0.02  # raw action units (actions lie in [-1, 1]): where every demo commands the same, e.g. full
# speed, the envelope has no width, and the open loop's 0.997 for their 1.0 should not count as leaving it
BLIND_IDLE_STEPS = 100  # idle steps after a blind plan, as the blind-replay measurement


@dataclass
class Demo:
    index: int
    actions: np.ndarray  # (N, 7)
    states: np.ndarray  # (N, S)
    ee_pos: np.ndarray  # (N, 3)
    ee_ori: np.ndarray  # (N, 3) axis-angle
    joints: np.ndarray  # (N, 7)
    gripper: np.ndarray  # (N, 2) finger joint positions
    model_xml: str


def demo_file(hdf5_root: Path, suite: str, task_name: str) -> Path:
    return Path(hdf5_root) / suite / f"{task_name}_demo.hdf5"


def read_demos(path: Path, indices: list[int]) -> list[Demo]:
    out = []
    with h5py.File(path, "r") as f:
        for i in indices:
            g = f[f"data/demo_{i}"]
            out.append(Demo(i, g["actions"][()], g["states"][()], g["obs/ee_pos"][()], g["obs/ee_ori"][()],
                            g["obs/joint_states"][()],
                            g["obs/gripper_states"][()], str(g.attrs["model_file"])))
    return out


def read_all_actions(path: Path) -> list[np.ndarray]:
    with h5py.File(path, "r") as f:
        names = sorted((k for k in f["data"] if k.startswith("demo_")), key=lambda k: int(k.split("_")[1]))
        return [f[f"data/{k}/actions"][()] for k in names]


def gripper_width(gripper: np.ndarray) -> np.ndarray:
    return gripper[:, 0] - gripper[:, 1]


def phase_bounds(actions: np.ndarray, ee_pos: np.ndarray) -> dict[str, int]:
    """Start step of each phase of one demonstration, from its gripper command and end-effector height.

    approach: until the gripper is first commanded closed; grasp: until the end effector has risen LIFT_RISE_M
    above where it closed; lift: until it is within TOP_MARGIN_M of its highest point before the release; carry/
    place: until the gripper is commanded open again; release: the rest. A phase that never starts begins at N.
    """
    n = len(actions)
    closed = actions[:, 6] > 0
    close = int(np.argmax(closed)) if closed.any() else n
    reopen = n
    if close < n:
        opened = np.nonzero(~closed[close:])[0]
        reopen = close + int(opened[0]) if len(opened) else n
    z = ee_pos[:, 2]
    lift = n
    if close < n:
        risen = np.nonzero(z[close:reopen] > z[close] + LIFT_RISE_M)[0]
        lift = close + int(risen[0]) if len(risen) else reopen
    carry = reopen
    if lift < reopen:
        top = z[lift:reopen].max()
        near = np.nonzero(z[lift:reopen] >= top - TOP_MARGIN_M)[0]
        carry = lift + int(near[0])
    return dict(zip(PHASES, (0, close, lift, carry, reopen), strict=True))


def phase_of(step: int, bounds: dict[str, int]) -> str:
    name = PHASES[0]
    for phase in PHASES:
        if step >= bounds[phase]:
            name = phase
    return name


def fixtures_from_model_xml(env, xml: str) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """The fixture poses a demonstration's saved scene XML holds (resets jitter fixtures outside the sim state)."""
    wanted = fixture_poses(env)
    root = ElementTree.fromstring(xml)
    out = {}
    for body in root.iter("body"):
        name = body.get("name")
        if name in wanted and body.get("pos") is not None:
            pos = np.array([float(v) for v in body.get("pos").split()])
            quat = np.array([float(v) for v in body.get("quat").split()]) if body.get("quat") else wanted[name][1]
            out[name] = (pos, quat)
    return out


def target_object(env) -> str:
    """The object the instruction asks to move (LIBERO's first object of interest)."""
    return env.env.obj_of_interest[0]


def simulate(env, demo: Demo, actions: np.ndarray, cap: int, stop_at_success: bool) -> dict[str, np.ndarray | int]:
    """Start from the demonstration's first state and run `actions` (then idle steps up to `cap` when they are
    fewer). Records, before each action as the demonstrations do, the end-effector position, joint angles,
    finger positions and the target object's position; `success_step` is the first step after which the task's
    goal holds (-1: never)."""
    env.reset()
    set_fixture_poses(env, fixtures_from_model_xml(env, demo.model_xml))
    obs = env.regenerate_obs_from_state(demo.states[0])
    # OSC's nullspace term pulls the arm toward the joints it held at reset: the demonstrations were recorded with
    # the reset's own (noisy) start there, so the start's joints take its place.
    env.env.robots[0].controller.update_initial_joints(demo.joints[0])
    target = target_object(env)
    rec = {k: [] for k in ("ee_pos", "ee_quat", "joints", "gripper", "object_pos")}
    success = -1
    for t in range(cap):
        rec["ee_pos"].append(np.asarray(obs["robot0_eef_pos"]).copy())
        rec["ee_quat"].append(np.asarray(obs["robot0_eef_quat"]).copy())
        rec["joints"].append(np.asarray(obs["robot0_joint_pos"]).copy())
        rec["gripper"].append(np.asarray(obs["robot0_gripper_qpos"]).copy())
        rec["object_pos"].append(np.asarray(obs[f"{target}_pos"]).copy())
        obs, *_ = env.step(actions[t] if t < len(actions) else IDLE)
        if success < 0 and env.check_success():
            success = t + 1
            if stop_at_success:
                break
    out = {k: np.stack(v) for k, v in rec.items()}
    out["success_step"] = success
    out["target"] = target
    return out


def first_run(mask: np.ndarray, run: int = 1) -> int:
    """First index where `mask` holds for `run` consecutive steps (-1: never)."""
    count = 0
    for i, m in enumerate(mask):
        count = count + 1 if m else 0
        if count >= run:
            return i - run + 1
    return -1


def orientation_error(quat_xyzw: np.ndarray, axis_angle: np.ndarray) -> np.ndarray:
    """Angle (rad) between end-effector orientations given as robosuite quaternions (x, y, z, w) and as the
    demonstrations' axis-angle vectors."""
    angle = np.linalg.norm(axis_angle, axis=-1, keepdims=True)
    axis = axis_angle / np.maximum(angle, 1e-12)
    demo_quat = np.concatenate([axis * np.sin(angle / 2), np.cos(angle / 2)], axis=-1)
    q = quat_xyzw / np.linalg.norm(quat_xyzw, axis=-1, keepdims=True)
    return 2 * np.arccos(np.clip(np.abs((q * demo_quat).sum(-1)), 0.0, 1.0))


def compare(rollout: dict, demo: Demo, bounds: dict[str, int]) -> dict:
    """A rollout against the demonstration's own trajectory, over the steps both have."""
    n = min(len(rollout["ee_pos"]), len(demo.ee_pos))
    ee = np.linalg.norm(rollout["ee_pos"][:n] - demo.ee_pos[:n], axis=1)
    angle = orientation_error(rollout["ee_quat"][:n], demo.ee_ori[:n])
    joint = np.linalg.norm(rollout["joints"][:n] - demo.joints[:n], axis=1)
    grip = np.abs(gripper_width(rollout["gripper"][:n]) - gripper_width(demo.gripper[:n]))
    separation = {}
    for threshold in SEPARATION_THRESHOLDS_M:
        step = first_run(ee > threshold)
        separation[f"{threshold * 100:g}cm"] = {"step": step, "phase": phase_of(step, bounds) if step >= 0 else None}
    per_phase = {}
    ends = [bounds[p] for p in PHASES[1:]] + [len(demo.ee_pos)]
    for phase, end in zip(PHASES, ends, strict=True):
        lo, hi = bounds[phase], min(end, n)
        if hi > lo:
            per_phase[phase] = {"steps": [lo, hi], "ee_mean_m": float(ee[lo:hi].mean()),
                                "ee_max_m": float(ee[lo:hi].max()), "ee_at_end_m": float(ee[hi - 1]),
                                "orientation_mean_rad": float(angle[lo:hi].mean()),
                                "joint_mean_rad": float(joint[lo:hi].mean()),
                                "joint_max_rad": float(joint[lo:hi].max())}
    obj = rollout["object_pos"]
    close = min(bounds["grasp"], n - 1)  # where the demonstration closes its gripper
    return {
        "at_demo_close": {"step": close, "ee_distance_m": float(ee[close]), "ee_dxyz_m":
                          (rollout["ee_pos"][close] - demo.ee_pos[close]).tolist(),
                          "orientation_error_rad": float(angle[close]),
                          "joint_error_per_joint_rad": (rollout["joints"][close] - demo.joints[close]).tolist()},
        "steps_compared": n,
        "success_step": int(rollout["success_step"]),
        "separation": separation,
        "per_phase": per_phase,
        "ee_mean_m": float(ee.mean()), "ee_max_m": float(ee.max()),
        "joint_mean_rad": float(joint.mean()), "joint_max_rad": float(joint.max()),
        "orientation_mean_rad": float(angle.mean()), "orientation_max_rad": float(angle.max()),
        "gripper_width_mean_abs_m": float(grip.mean()),
        "object_rise_max_m": float(obj[:, 2].max() - obj[0, 2]),
        "object_moved_xy_max_m": float(np.linalg.norm(obj[:, :2] - obj[0, :2], axis=1).max()),
        "min_ee_height_m": float(rollout["ee_pos"][:, 2].min()),
        "curves": {"ee_distance_m": ee, "joint_error_rad": joint, "orientation_error_rad": angle},
    }


def offline_actions(open_loop: np.ndarray, demos: list[np.ndarray]) -> dict:
    """Open-loop actions (raw units) against every demonstration of the task, per step.

    `mse_vs_demos`: mean over the demonstrations still running at that step of the squared error (mean over the 7
    dimensions); `mse_vs_mean`: against the time-aligned mean demonstration; `demo_spread`: the demonstrations'
    own mean squared distance from that mean (what no observation-blind chain can get below); the envelope is the
    demonstrations' min and max per step and dimension, where at least ENVELOPE_MIN_DEMOS of them still run.
    """
    longest = max(len(a) for a in demos)
    horizon = min(longest, len(open_loop))
    stack = np.full((len(demos), longest, 7), np.nan)
    for i, a in enumerate(demos):
        stack[i, :len(a)] = a
    active = (~np.isnan(stack[..., 0])).sum(0)
    enough = active >= ENVELOPE_MIN_DEMOS * len(demos)
    horizon = min(horizon, int(np.nonzero(enough)[0].max()) + 1)
    stack = stack[:, :horizon]
    ol = open_loop[:horizon]
    mean = np.nanmean(stack, axis=0)
    sq = (stack - ol[None]) ** 2  # (demos, T, 7)
    mse_vs_demos = np.nanmean(sq.mean(-1), axis=0)
    mse_vs_mean = ((ol - mean) ** 2).mean(-1)
    spread = np.nanmean(((stack - mean[None]) ** 2).mean(-1), axis=0)
    low, high = np.nanmin(stack, axis=0), np.nanmax(stack, axis=0)
    std = np.nanstd(stack, axis=0)
    outside = (ol < low - ENVELOPE_MARGIN) | (ol > high + ENVELOPE_MARGIN)  # (T, 7)
    exits = {str(k): first_run(outside[:, k], EXIT_RUN) for k in range(7)}
    z = np.abs(ol - mean) / np.maximum(std, 1e-6)
    return {
        "horizon": horizon,
        "mse_vs_demos": mse_vs_demos, "mse_vs_mean": mse_vs_mean, "demo_spread": spread,
        "mean": mean, "low": low, "high": high, "std": std,
        "inside_fraction_per_dim": (~outside).mean(0).tolist(),
        "inside_fraction_all_dims": float((~outside).all(1).mean()),
        "first_exit_step_per_dim": exits,
        "first_exit_step_any_dim": first_run(outside.any(1), EXIT_RUN),
        "median_abs_z_per_dim": np.median(z, axis=0).tolist(),
    }


def median_bounds(all_bounds: list[dict[str, int]]) -> dict[str, int]:
    return {p: int(np.median([b[p] for b in all_bounds])) for p in PHASES}


def phase_means(curve: np.ndarray, bounds: dict[str, int]) -> dict[str, float]:
    ends = [bounds[p] for p in PHASES[1:]] + [len(curve)]
    return {p: float(np.mean(curve[bounds[p]:min(e, len(curve))])) for p, e in zip(PHASES, ends, strict=True)
            if min(e, len(curve)) > bounds[p]}


class OpenLoop:
    """A checkpoint's exact open-loop actions per instruction, raw units (through its postprocessor)."""

    def __init__(self, checkpoint: Path):
        self.checkpoint = Path(checkpoint)
        self.policy = PredVLAPolicy.from_pretrained(self.checkpoint).eval()
        self.policy.config.er_iterations = 0
        self.postprocessor = load_postprocessor(self.checkpoint)
        self.artefact = FrontendArtefact.load(self.checkpoint / "predvla_frontend")
        self._encoder = None

    def language(self, instruction: str):
        if self._encoder is None:
            self._encoder = LanguageEncoder("cpu", verbose=False)
        with torch.no_grad():
            return self.artefact.language.transform(torch.from_numpy(self._encoder([instruction])))

    def normalised(self, instruction: str, steps: int):
        return open_loop(self.policy, self.language(instruction), steps)[:, 0]  # (steps, 7)

    def actions(self, instruction: str, steps: int) -> np.ndarray:
        with torch.no_grad():
            raw = self.postprocessor(self.normalised(instruction, steps))
        return raw.detach().cpu().double().numpy()


EFFECT_WINDOWS = ((0, 5), (5, 10), (10, 20), (20, 50), (50, None))


def instruction_effect(own: np.ndarray, others: list[np.ndarray], horizon: int) -> np.ndarray:
    """Per step, the mean over `others` of the squared difference from `own` (mean over the 7 dimensions), NaN where
    an other sequence has ended: how much the instruction changes the actions at each step."""
    diffs = np.full((len(others), horizon), np.nan)
    for i, other in enumerate(others):
        k = min(horizon, len(other), len(own))
        diffs[i, :k] = ((own[:k] - other[:k]) ** 2).mean(-1)
    if not len(others):
        return np.full(horizon, np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # steps where every other sequence has ended: NaN
        return np.nanmean(diffs, axis=0)


def window_means(curve: np.ndarray) -> dict[str, float]:
    out = {}
    for lo, hi in EFFECT_WINDOWS:
        part = curve[lo:hi]
        if len(part) and not np.isnan(part).all():
            out[f"{lo}-{hi if hi is not None else len(curve)}"] = float(np.nanmean(part))
    return out


def mean_demo(actions: list[np.ndarray]) -> np.ndarray:
    """Time-aligned mean of demonstrations, up to the step where fewer than ENVELOPE_MIN_DEMOS of them run."""
    longest = max(len(a) for a in actions)
    stack = np.full((len(actions), longest, 7), np.nan)
    for i, a in enumerate(actions):
        stack[i, :len(a)] = a
    enough = (~np.isnan(stack[..., 0])).sum(0) >= ENVELOPE_MIN_DEMOS * len(actions)
    return np.nanmean(stack[:, :int(np.nonzero(enough)[0].max()) + 1], axis=0)


def run_task(open_loop: OpenLoop, hdf5_root: Path, task_id: int, demos: int, cap: int, suite: str = "libero_object",
             log=print, other_open_loops: dict[int, np.ndarray] | None = None,
             other_mean_demos: dict[int, np.ndarray] | None = None) -> tuple[dict, dict]:
    """The simulator and offline comparisons of one task: (numbers for the JSON, arrays for the figure)."""
    spec = task_spec(suite, task_id)
    path = demo_file(hdf5_root, suite, spec.name)
    all_actions = read_all_actions(path)
    n_file = len(all_actions)
    chosen = list(range(min(demos, n_file)))
    chosen_demos = read_demos(path, chosen)
    ol = open_loop.actions(spec.language, cap)
    env = make_env(spec)
    rows, curves = [], []
    for demo in chosen_demos:
        bounds = phase_bounds(demo.actions, demo.ee_pos)
        other = (demo.index + 1) % n_file
        rollouts = {
            "replay": simulate(env, demo, demo.actions, len(demo.actions), stop_at_success=False),
            "open_loop": simulate(env, demo, ol, cap, stop_at_success=True),
        }
        # The open loop with its rotation commands replaced by the demonstration's own (zero past its end): how much
        # of the failure the end effector's orientation carries.
        own_rotation = ol.copy()
        own_rotation[:, 3:6] = 0.0
        k = min(len(ol), len(demo.actions))
        own_rotation[:k, 3:6] = demo.actions[:k, 3:6]
        rollouts["open_loop_demo_rotation"] = simulate(env, demo, own_rotation, cap, stop_at_success=True)
        if other != demo.index:
            rollouts["blind_plan"] = simulate(env, demo, all_actions[other],
                                              min(cap, len(all_actions[other]) + BLIND_IDLE_STEPS),
                                              stop_at_success=True)
        cmp = {name: compare(r, demo, bounds) for name, r in rollouts.items()}
        steps = min(len(demo.actions), len(ol))
        action_err = ((ol[:steps] - demo.actions[:steps]) ** 2).mean(-1)
        row = {"demo": demo.index, "length": len(demo.actions), "phases": bounds,
               "blind_plan_demo": other if other != demo.index else None,
               "open_loop_action_mse_vs_this_demo": float(action_err.mean()),
               "open_loop_action_mse_vs_this_demo_per_phase": phase_means(action_err, bounds),
               "open_loop_first_close_step": int(np.argmax(ol[:, 6] > 0)) if (ol[:, 6] > 0).any() else -1,
               # Translation commands summed up to the demonstration's close step (action units; OSC_POSE moves the
               # target 5 cm per unit and step): how far each asks the hand to go before grasping.
               "commanded_xyz_sum_to_demo_close": {
                   "open_loop": ol[:bounds["grasp"], :3].sum(0).tolist(),
                   "demo": demo.actions[:bounds["grasp"], :3].sum(0).tolist()},
               **{name: {k: v for k, v in c.items() if k != "curves"} for name, c in cmp.items()}}
        rows.append(row)
        curves.append({"demo": demo, "bounds": bounds, "rollouts": rollouts, "cmp": cmp, "action_err": action_err})
        sep = cmp["open_loop"]["separation"]
        log(f"task {task_id} demo {demo.index}: open loop leaves the demo by 2 cm at step {sep['2cm']['step']} "
            f"({sep['2cm']['phase']}), 5 cm at {sep['5cm']['step']} ({sep['5cm']['phase']}); success step "
            f"{cmp['open_loop']['success_step']} (with the demo's rotation: "
            f"{cmp['open_loop_demo_rotation']['success_step']}"
            f"; another demo's plan: {cmp.get('blind_plan', {}).get('success_step')}); own replay max "
            f"{cmp['replay']['ee_max_m'] * 100:.2f} cm")
    env.close()
    all_bounds = []
    with h5py.File(path, "r") as f:
        for k in range(n_file):
            g = f[f"data/demo_{k}"]
            all_bounds.append(phase_bounds(g["actions"][()], g["obs/ee_pos"][()]))
    offline = offline_actions(ol, all_actions)
    med = median_bounds(all_bounds)
    h = offline["horizon"]
    others = {k: v for k, v in (other_open_loops or {}).items() if k != task_id}
    other_demos = {k: v for k, v in (other_mean_demos or {}).items() if k != task_id}
    offline["instruction_effect_open_loop"] = instruction_effect(ol, list(others.values()), h)
    offline["instruction_effect_demos"] = instruction_effect(mean_demo(all_actions), list(other_demos.values()), h)
    exits = offline["first_exit_step_per_dim"]
    numbers = {
        "task_id": task_id, "task": spec.name, "instruction": spec.language, "demo_file": str(path),
        "demos_in_file": n_file, "demos_simulated": chosen,
        "median_phase_starts_all_demos": med,
        "demos": rows,
        "offline": {
            "horizon": offline["horizon"],
            "open_loop_mse_vs_demos": float(np.mean(offline["mse_vs_demos"])),
            "open_loop_mse_vs_mean_demo": float(np.mean(offline["mse_vs_mean"])),
            "demo_spread_mse": float(np.mean(offline["demo_spread"])),
            "per_phase": {
                "open_loop_mse_vs_demos": phase_means(offline["mse_vs_demos"], med),
                "open_loop_mse_vs_mean_demo": phase_means(offline["mse_vs_mean"], med),
                "demo_spread_mse": phase_means(offline["demo_spread"], med),
            },
            "inside_envelope_fraction_per_dim": offline["inside_fraction_per_dim"],
            "inside_envelope_fraction_all_dims": offline["inside_fraction_all_dims"],
            "first_exit_step_per_dim": exits,
            "first_exit_phase_per_dim": {k: (phase_of(s, med) if s >= 0 else None) for k, s in exits.items()},
            "first_exit_step_any_dim": offline["first_exit_step_any_dim"],
            "median_abs_z_per_dim": offline["median_abs_z_per_dim"],
            # How much the instruction changes the actions, by step window: this task's open loop against the open
            # loop under each other instruction of the suite, and its mean demonstration against the other tasks'
            # mean demonstrations (those whose files exist).
            "instruction_effect": {
                "open_loop_vs_other_instructions": window_means(offline["instruction_effect_open_loop"]),
                "mean_demo_vs_other_tasks": window_means(offline["instruction_effect_demos"]),
                "other_instructions": sorted(others), "other_tasks_with_demos": sorted(other_demos)},
        },
    }
    return numbers, {"curves": curves, "offline": offline, "open_loop": ol, "median_bounds": med, "spec": spec}
