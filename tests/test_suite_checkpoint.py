"""The quickstart's libero_object suite checkpoint loads through LeRobot's own `make_policy` path and acts on a real
LIBERO observation (`lerobot-eval --policy.path=checkpoints/predvla_libero_object_reading`)."""

from pathlib import Path

import numpy as np
import pytest
import torch

pytestmark = pytest.mark.simulator

CHECKPOINT = Path(__file__).parents[1] / "checkpoints" / "predvla_libero_object_reading"


def test_suite_checkpoint_loads_with_make_policy_and_acts_on_libero():
    from lerobot.configs.policies import PreTrainedConfig
    from lerobot.envs.utils import preprocess_observation
    from lerobot.policies.factory import make_policy, make_pre_post_processors

    from lerobot_predvla.sims.libero.env_config import PredVLALiberoEnv

    assert not (CHECKPOINT / "posterior_store.safetensors").exists()  # training posteriors are never shipped
    config = PreTrainedConfig.from_pretrained(CHECKPOINT)
    config.pretrained_path = CHECKPOINT
    env_cfg = PredVLALiberoEnv(task="libero_object", task_ids=[3])
    policy = make_policy(config, env_cfg=env_cfg)
    assert sum(p.numel() for p in policy.parameters()) == 675_732
    pre, post = make_pre_post_processors(config, pretrained_path=str(CHECKPOINT))
    env_pre, env_post = env_cfg.get_env_processors()
    venv = env_cfg.create_envs(n_envs=1)["libero_object"][3]
    try:
        obs, _ = venv.reset(seed=[0])
        policy.reset()
        for _ in range(2):
            # As lerobot-eval: the task string from the sub-environment beside the observation.
            observation = {**preprocess_observation(obs), "task": list(venv.call("task_description"))}
            assert observation["task"] == ["pick up the bbq sauce and place it in the basket"]
            with torch.inference_mode():
                action = post(policy.select_action(pre(env_pre(observation))))
            assert action.shape == (1, 7) and torch.isfinite(action).all()
            obs, *_ = venv.step(np.asarray(action))
    finally:
        venv.close()


def test_readme_quickstart_runs_as_written_with_fewer_steps(tmp_path):
    """README's quickstart command, as written, with a 6-step cap and its output folder under tmp_path: both tasks,
    2 episodes each, and no device warning (the shipped config leaves the device unset)."""
    import json
    import os
    import shlex
    import subprocess
    import sys

    readme = (CHECKPOINT.parents[1] / "README.md").read_text()
    section = readme[readme.index("## Quickstart"):]
    start = section.index("```bash\n") + len("```bash\n")
    block = section[start:section.index("\n```", start)].replace("\\\n", " ")
    (command,) = [line for line in block.splitlines() if line.startswith("lerobot-eval ")]
    argv = shlex.split(command)
    assert "--output_dir=outputs/quickstart" in argv
    argv = [a if not a.startswith("--output_dir=") else f"--output_dir={tmp_path / 'quickstart'}" for a in argv]
    argv[0] = str(Path(sys.executable).parent / argv[0])
    result = subprocess.run([*argv, "--env.episode_length=6"], cwd=CHECKPOINT.parents[1], capture_output=True,
                            text=True, timeout=900, env={**os.environ, "HF_HUB_OFFLINE": "1"})
    assert result.returncode == 0, result.stderr[-3000:]
    info = json.loads((tmp_path / "quickstart" / "eval_info.json").read_text())
    assert [t["task_id"] for t in info["per_task"]] == [0, 1] and info["overall"]["n_episodes"] == 4
    assert "is not available" not in result.stdout + result.stderr
