"""The command lines of LeRobot's `lerobot-train` and `lerobot-eval`, built here for every caller: the sweep runner,
`predvla demo synthetic`, `predvla demo libero`, `predvla demo robot`, the kill-and-resume harness and the model
card's evaluation command; and how those callers start the plugin's own `predvla` command.

Each command puts its flags in one order (draccus reads them in any): the program, the policy, the data or
environment, the output folder, the run's numbers, then the caller's `extra` flags, which LeRobot lets override any
earlier one.
"""

import json
import sys
from pathlib import Path

BIN = Path(sys.executable).parent  # the environment's console scripts
LEROBOT_TRAIN = str(BIN / "lerobot-train")
LEROBOT_EVAL = str(BIN / "lerobot-eval")
ACCELERATE = str(BIN / "accelerate")
TORCHRUN = str(BIN / "torchrun")
PREDVLA = [sys.executable, "-m", "lerobot_predvla.cli.main"]  # the plugin's `predvla` command, on this Python
MAPPING_FIELDS = ("normalization_mapping",)  # config fields of type dict, set whole on the command line


def field_args(values: dict, prefix: str = "policy") -> list[str]:
    """{"tau": [30, 14, 8, 2], "x": {"y": 1}} -> ["--policy.tau=[30,14,8,2]", "--policy.x.y=1"]; a dict-typed field
    (MAPPING_FIELDS, e.g. `normalization_mapping`) is passed whole as JSON, the only form draccus parses for it."""
    args = []
    for key, value in values.items():
        if key in MAPPING_FIELDS:
            args.append(f"--{prefix}.{key}={json.dumps(value)}")
        elif isinstance(value, dict):
            args += field_args(value, f"{prefix}.{key}")
        elif isinstance(value, bool):
            args.append(f"--{prefix}.{key}={str(value).lower()}")
        elif isinstance(value, list | tuple):
            args.append(f"--{prefix}.{key}=[{','.join(map(str, value))}]")
        elif value is not None:
            args.append(f"--{prefix}.{key}={value}")
    return args


def policy_args(policy_type: str, fields: dict | None = None) -> list[str]:
    """`--policy.type=...` and the policy's fields."""
    return [f"--policy.type={policy_type}", *field_args(fields or {})]


def launcher(
    processes: int = 1,
    device: str = "cuda",
    lerobot_train: str = LEROBOT_TRAIN,
    accelerate: str = ACCELERATE,
    torchrun: str = TORCHRUN,
) -> list[str]:
    """`lerobot-train`, or for several processes LeRobot's multi-GPU path `accelerate launch --multi_gpu`; on the CPU
    `torchrun` (accelerate's Accelerator then runs DDP over gloo: `accelerate launch --cpu` starts one process only)."""
    if processes == 1:
        return [lerobot_train]
    if device == "cpu":
        return [torchrun, f"--nproc_per_node={processes}", lerobot_train]
    return [accelerate, "launch", "--multi_gpu", f"--num_processes={processes}", lerobot_train]


def train_command(
    *,
    policy: list[str],
    dataset_repo_id: str,
    dataset_root: Path | str | None,
    output_dir: Path,
    steps: int,
    batch_size: int,
    save_freq: int,
    device: str,
    seed: int | None = None,
    job_name: str | None = None,
    program: list[str] | None = None,
    extra: list[str] | tuple[str, ...] = (),
) -> list[str]:
    """A `lerobot-train` from scratch (`program`: `launcher()`'s words, default `lerobot-train` alone); never pushes
    to the Hub nor logs to Weights & Biases. `batch_size` is per process."""
    return [
        *(program or [LEROBOT_TRAIN]),
        *policy,
        f"--dataset.repo_id={dataset_repo_id}",
        *([f"--dataset.root={dataset_root}"] if dataset_root else []),
        f"--output_dir={output_dir}",
        *([f"--job_name={job_name}"] if job_name is not None else []),
        *([f"--seed={seed}"] if seed is not None else []),
        f"--steps={steps}",
        f"--batch_size={batch_size}",
        f"--save_freq={save_freq}",
        f"--policy.device={device}",
        "--policy.push_to_hub=false",
        "--wandb.enable=false",
        *extra,
    ]


def resume_args(config_path: Path) -> list[str]:
    """The flags that resume a training from a checkpoint's `train_config.json` (or its `pretrained_model` folder)."""
    return [f"--config_path={config_path}", "--resume=true"]


def eval_command(
    *,
    checkpoint: Path | str,
    env_type: str,
    suite: str,
    n_episodes: int,
    batch_size: int,
    output_dir: Path | str,
    device: str | None = None,
    policy: list[str] | tuple[str, ...] = (),
    episode_length: int | None = None,
    init_states: bool | None = None,
    seed: int | None = None,
    program: str = LEROBOT_EVAL,
    extra: list[str] | tuple[str, ...] = (),
) -> list[str]:
    """A `lerobot-eval` of `checkpoint` on a LIBERO suite, environments stepped in the calling process; `device` None
    lets LeRobot pick it, `policy` holds `--policy.*` overrides."""
    return [
        program,
        f"--policy.path={checkpoint}",
        *([f"--policy.device={device}"] if device is not None else []),
        *policy,
        f"--env.type={env_type}",
        f"--env.task={suite}",
        *([f"--env.episode_length={episode_length}"] if episode_length is not None else []),
        *([f"--env.init_states={str(init_states).lower()}"] if init_states is not None else []),
        f"--eval.n_episodes={n_episodes}",
        f"--eval.batch_size={batch_size}",
        "--eval.use_async_envs=false",
        *([f"--seed={seed}"] if seed is not None else []),
        f"--output_dir={output_dir}",
        *extra,
    ]
