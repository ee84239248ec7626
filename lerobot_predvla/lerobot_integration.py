"""Every change this plugin makes to LeRobot 0.6.1 (and its LIBERO) beyond registering its types, installed by one call.

Registration goes through LeRobot's own extension points and needs nothing here: the policy types
(`PreTrainedConfig.register_subclass`, resolved by module name), the `predvla_libero` env type
(`EnvConfig.register_subclass`, whose `get_env_processors` gives its processors), the processor steps
(`ProcessorStepRegistry`) and the replay robot and camera. What LeRobot offers no extension point for is changed
by `install()`, which `lerobot_predvla/__init__.py` calls once, after registering the types. Each change below says
what it replaces, why, and the upstream change that would make it unnecessary; docs/lerobot_integration.md lists
them for users.
"""

import functools
import logging
import os
import sys
from pathlib import Path

import lerobot.envs.factory
from lerobot.envs.configs import EnvConfig, LiberoEnv
from lerobot.scripts import lerobot_eval
from lerobot.utils.constants import CHECKPOINTS_DIR

from lerobot_predvla.columns import GRIPPER_DIM, JOINT_DIM, LEROBOT_LIBERO_STATE_DIM
from lerobot_predvla.policies.common.cached_features import CachedFeaturesConfig
from lerobot_predvla.sims.libero.config_path import use_venv_config
from lerobot_predvla.sims.libero.env_config import PredVLALiberoEnv, fault_summary, libero_env_processors
from lerobot_predvla.sims.libero.instructions import instruction_summary
from lerobot_predvla.sims.libero.object_shift import shift_summary
from lerobot_predvla.sims.libero.protocol import EVAL_ENV_TYPE
from lerobot_predvla.utils.checkpoints import (
    remove_leftovers,
    save_checkpoint_atomically,
    update_last_checkpoint_atomically,
)
from lerobot_predvla.utils.run_lock import lock_output_dir

LEROBOT_TRAIN = "lerobot.scripts.lerobot_train"
HOOKS_ENV = "PREDVLA_LEROBOT_TRAIN_HOOKS"  # "0": leave `lerobot-train` exactly as LeRobot ships it
_INSTALLED = "_predvla_hooks_installed"
# The modules that bind LeRobot's `make_env_pre_post_processors` by name: the factory, its package, and the CLI
# scripts (loaded before plugins when run as `lerobot-eval` / `lerobot-train`; imported later, they take it from the
# package).
_ENV_PROCESSOR_MODULES = ("lerobot.envs.factory", "lerobot.envs", "lerobot.scripts.lerobot_eval",
                          "lerobot.scripts.lerobot_train")

_lerobot_make_env_pre_post_processors = lerobot.envs.factory.make_env_pre_post_processors
_lerobot_eval_policy_all = lerobot_eval.eval_policy_all


# ----- environment variables ---------------------------------------------------------------------------------
def point_libero_at_venv_config() -> bool:
    """Set `LIBERO_CONFIG_PATH` to this virtual environment's LIBERO config (`make libero` writes it) unless the user
    set it; child processes inherit it. True when it did.

    Replaces: hf-libero's default `~/.libero/config.yaml`, one file per user.
    Why: the last `make libero` of any checkout points that file at its own environment's assets, and once that
    environment is gone every other checkout's simulator fails at import (sims/libero/config_path.py).
    Upstream: hf-libero reading a config inside its own installation (or its package data) before `~/.libero`.
    """
    return use_venv_config()


# ----- lerobot-eval ------------------------------------------------------------------------------------------
def make_env_pre_post_processors(env_cfg: EnvConfig, policy_cfg) -> tuple:
    """LeRobot's `make_env_pre_post_processors`, with PredVLA's LIBERO step for this plugin's policies.

    Replaces: `lerobot.envs.factory.make_env_pre_post_processors` where it is bound by name
    (`_ENV_PROCESSOR_MODULES`).
    Why: LeRobot chooses env processors by env config (`EnvConfig.get_env_processors`, which `predvla_libero` uses)
    except for a policy special case (X-VLA on LIBERO) written into this function. With LeRobot's own
    `--env.type=libero`, a policy trained on LIBERO's hdf5 demonstrations (joints 7 + gripper 2) needs PredVLA's
    step instead of LeRobot's 8-dim end-effector state; a policy trained on another state size gets one clear error
    with `predvla_libero`. Every other policy and env type gets LeRobot's processors unchanged.
    Upstream: a policy-config hook in this function (e.g. `PreTrainedConfig.env_processors(env_cfg)`, returning
    None to keep the env's), which would also carry X-VLA's special case.
    """
    ours = isinstance(policy_cfg, CachedFeaturesConfig)
    if isinstance(env_cfg, PredVLALiberoEnv) and ours and policy_cfg.proprio_dim != JOINT_DIM + GRIPPER_DIM:
        raise ValueError(
            f"--env.type={EVAL_ENV_TYPE} gives a joints + gripper state ({JOINT_DIM + GRIPPER_DIM}); this policy was "
            f"trained on a {policy_cfg.proprio_dim}-dim observation.state: evaluate it with --env.type=libero."
        )
    if type(env_cfg) is LiberoEnv and ours:
        if policy_cfg.proprio_dim == JOINT_DIM + GRIPPER_DIM:
            return libero_env_processors()
        if policy_cfg.proprio_dim != LEROBOT_LIBERO_STATE_DIM:
            raise ValueError(
                f"This policy was trained on a {policy_cfg.proprio_dim}-dim observation.state; LIBERO offers joints + "
                f"gripper ({JOINT_DIM + GRIPPER_DIM}, LIBERO's hdf5 demonstrations) or LeRobot's end-effector state "
                f"({LEROBOT_LIBERO_STATE_DIM}, the community LeRobot datasets)."
            )
    return _lerobot_make_env_pre_post_processors(env_cfg, policy_cfg)


def eval_policy_all(envs: dict, policy, env_preprocessor, *args, **kwargs) -> dict:
    """LeRobot's `eval_policy_all`, plus the `predvla_faults` section (written into eval_info.json): faulted episodes
    with their reasons, non-finite actions, observations the policy masked, actions it replaced, injected faults; and
    with shifted objects (`--env.object_shift_cm`, `--env.placement_spread_cm`), the `predvla_shifts` section: every
    episode's shift and whether the shifted bodies settled where they were put; and the `predvla_instructions` section:
    each task's own instruction and the one it was run with (`--env.instruction_from_task`, `--env.instruction_shift`).

    Replaces: `lerobot.scripts.lerobot_eval.eval_policy_all` (which `lerobot-eval` calls from its own module, and
    `lerobot-train`'s periodic evaluation through the name it imported, left unchanged).
    Why: LeRobot writes `eval_info.json` from this function's result only; neither an env nor a policy can add to it.
    Upstream: a way for an env or policy to contribute a section to `eval_info.json` (e.g. an `eval_info()` method
    called after the rollouts).
    """
    info = _lerobot_eval_policy_all(envs, policy, env_preprocessor, *args, **kwargs)
    info["predvla_faults"] = fault_summary(envs, policy, env_preprocessor)
    instructions = instruction_summary(envs)
    if instructions:
        info["predvla_instructions"] = instructions
    shifts = shift_summary(envs)
    if shifts is not None:
        info["predvla_shifts"] = shifts
    return info


def install_eval_changes() -> None:
    """Put `make_env_pre_post_processors` and `eval_policy_all` above in place (idempotent)."""
    lerobot_eval.eval_policy_all = eval_policy_all
    for name in _ENV_PROCESSOR_MODULES:
        module = sys.modules.get(name)
        if getattr(module, "make_env_pre_post_processors", None) is _lerobot_make_env_pre_post_processors:
            module.make_env_pre_post_processors = make_env_pre_post_processors


# ----- lerobot-train -----------------------------------------------------------------------------------------
def _is_main_process() -> bool:
    return int(os.environ.get("RANK", "0")) == 0  # torchrun / accelerate launch set RANK per process


def hold_output_dir(output_dir: Path) -> None:
    """Take the run's lock (once per process) and clear what killed checkpoint writes left behind."""
    output_dir = Path(output_dir)
    lock_output_dir(output_dir)
    if (output_dir / CHECKPOINTS_DIR).is_dir():
        remove_leftovers(output_dir / CHECKPOINTS_DIR)


def _lerobot_train_modules() -> list:
    main = sys.modules.get("__main__")
    found = [sys.modules.get(LEROBOT_TRAIN)]
    if main is not None and getattr(getattr(main, "__spec__", None), "name", None) == LEROBOT_TRAIN:
        found.append(main)  # python -m lerobot.scripts.lerobot_train
    return [m for m in found if m is not None and not getattr(m, _INSTALLED, False)]


def install_lerobot_train_hooks() -> bool:
    """Inside `lerobot-train` only: atomic checkpoints and one training per output folder. Replaces three names in
    the namespace of a loaded `lerobot.scripts.lerobot_train` (LeRobot's source and every other caller are left as
    they are); True if it was done now. `PREDVLA_LEROBOT_TRAIN_HOOKS=0` leaves `lerobot-train` as LeRobot ships it.

    Replaces, in that namespace (Why: LeRobot 0.6.1 offers a policy no hook around checkpoint writing, nor any that
    sees the output folder):
    - `save_checkpoint`: LeRobot's writes a step's files in place, so a kill leaves a half-written step beside the
      good ones; here LeRobot's own writes into a staging folder that gets SHA-256 manifests and is renamed into
      place once complete (utils/checkpoints.py, utils/manifest.py);
    - `update_last_checkpoint`: LeRobot's unlinks `last` and then creates it, so a kill in between leaves nothing to
      resume from; here a new link is renamed over the old one;
    - `make_train_eval_datasets` (the first call that receives the resolved train config): LeRobot's own, after
      taking the output folder's lock (utils/run_lock.py) when the folder exists (a resume), since nothing stops two
      trainings writing into one folder; a fresh run takes it at its first checkpoint, when LeRobot creates it.
    Upstream: atomic checkpoint writes (staging folder + rename, `os.replace` of the `last` link) and a lock on the
    output folder in LeRobot's `lerobot.common.train_utils` and `lerobot-train`.
    """
    if os.environ.get(HOOKS_ENV, "1") == "0":
        return False
    modules = _lerobot_train_modules()
    for module in modules:
        lerobot_save, lerobot_datasets = module.save_checkpoint, module.make_train_eval_datasets

        @functools.wraps(lerobot_save)
        def save_checkpoint(checkpoint_dir, *args, _save=lerobot_save, **kwargs):
            hold_output_dir(Path(checkpoint_dir).parent.parent)  # OUTPUT_DIR/checkpoints/<step>
            save_checkpoint_atomically(_save, checkpoint_dir, *args, **kwargs)

        @functools.wraps(lerobot_datasets)
        def make_train_eval_datasets(cfg, *args, _make=lerobot_datasets, **kwargs):
            if _is_main_process() and cfg.output_dir is not None and Path(cfg.output_dir).is_dir():
                hold_output_dir(Path(cfg.output_dir))
            return _make(cfg, *args, **kwargs)

        module.save_checkpoint = save_checkpoint
        module.update_last_checkpoint = update_last_checkpoint_atomically
        module.make_train_eval_datasets = make_train_eval_datasets
        setattr(module, _INSTALLED, True)
        logging.debug("PredVLA: atomic checkpoints and the output-folder lock installed in %s", module.__name__)
    return bool(modules)


def install() -> None:
    """Make every change above: the one call, from the package's registration (`lerobot_predvla/__init__.py`)."""
    point_libero_at_venv_config()
    install_eval_changes()
    install_lerobot_train_hooks()
