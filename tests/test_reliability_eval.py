"""Faults at evaluation time with the real simulator (docs/reliability.md): a faulted LIBERO episode ends as a
failure with its reason while the run goes on; injected sensor faults never produce a non-finite action."""

import json
import sys

import numpy as np
import pytest
import torch
from lerobot.processor import PolicyProcessorPipeline
from libero_factory import BIN, run
from test_libero_eval import EPISODE_STEPS, SOUP, SUITE, checkpoint  # noqa: F401  (module fixture)

from lerobot_predvla.columns import OBS_VISION_FEATURES
from lerobot_predvla.frontend import FrozenFrontend
from lerobot_predvla.frontend.processor_step import FrontendProcessorStep
from lerobot_predvla.sims.libero.fault_injection import FaultInjectionStep

pytestmark = [pytest.mark.simulator, pytest.mark.slow]

# Run lerobot-eval's own entry point with LiberoEnv.step patched: sub-environment 1 raises at its 2nd step of
# the first rollout, sub-environment 0 gets a NaN joint position at its 3rd step of the second rollout.
FAULTY_EVAL = """
import sys
import lerobot.envs.libero as libero

real_step = libero.LiberoEnv.step

def step(self, action):
    rollout = getattr(self, "_rollouts", 0)
    if self.episode_index == 1 and rollout == 1 and self._steps_since_reset == 2:
        raise RuntimeError("simulated MuJoCo fault")
    result = real_step(self, action)
    if self.episode_index == 0 and rollout == 2 and self._steps_since_reset == 3:
        self._env.env.sim.data.qpos[0] = float("nan")
    return result

libero.LiberoEnv.step = step
from lerobot.scripts.lerobot_eval import main
sys.argv = ["lerobot-eval", *sys.argv[1:]]
main()
"""


def eval_args(path, out, *extra: str) -> list[str]:
    return [f"--policy.path={path}", "--env.type=predvla_libero", f"--env.task={SUITE}", "--env.task_ids=[0]",
            f"--env.episode_length={EPISODE_STEPS}", "--eval.use_async_envs=false", "--policy.device=cpu",
            f"--output_dir={out}", *extra]


def test_a_faulted_episode_ends_as_a_failure_and_the_run_goes_on(checkpoint, tmp_path):  # noqa: F811
    script = tmp_path / "faulty_eval.py"
    script.write_text(FAULTY_EVAL)
    log = run([sys.executable, str(script),
               *eval_args(checkpoint, tmp_path / "out", "--eval.n_episodes=4", "--eval.batch_size=2")])
    info = json.loads((tmp_path / "out" / "eval_info.json").read_text())
    assert info["overall"]["n_episodes"] == 4, log[-2000:]
    faults = info["predvla_faults"]
    episodes = faults["faulted_episodes"]
    assert [(f["episode_ix"], f["step"]) for f in episodes] == [(1, 2), (2, 3)], episodes
    assert "RuntimeError: simulated MuJoCo fault" in episodes[0]["reason"]
    assert "non-finite simulator state (qpos)" in episodes[1]["reason"]
    assert all(f["suite"] == SUITE and f["task_id"] == 0 for f in episodes)
    successes = info["per_task"][0]["metrics"]["successes"]
    assert len(successes) == 4 and not successes[1] and not successes[2]
    assert faults["nonfinite_actions"] == 0


@pytest.mark.parametrize("mode", ["nan", "drop"])
def test_fault_injection_never_gives_a_nonfinite_action(checkpoint, tmp_path, mode):  # noqa: F811
    log = run([str(BIN / "lerobot-eval"), *eval_args(checkpoint, tmp_path, "--eval.n_episodes=2",
               "--eval.batch_size=2", "--env.fault_rate=0.5", f"--env.fault_mode={mode}", "--env.fault_seed=3")])
    faults = json.loads((tmp_path / "eval_info.json").read_text())["predvla_faults"]
    assert faults["nonfinite_actions"] == 0 and faults["faulted_episodes"] == [], log[-2000:]
    injected = faults["injected"]
    assert injected["mode"] == mode and injected["rate"] == 0.5 and injected["steps"] == 2 * EPISODE_STEPS
    assert 0 < injected["vision"] < injected["steps"] and 0 < injected["proprio"] < injected["steps"]
    policy = faults["policy"]
    assert policy["observation.state"] == injected["proprio"]  # every spoiled reading was masked
    assert policy["observation.vision_features"] > 0 and policy["fallback_actions"] == 0


def test_fault_injection_rate_and_modes():
    state = torch.zeros(4, 9)
    image = torch.zeros(4, 3, 8, 8)
    step = FaultInjectionStep(rate=0.2, mode="nan", seed=0)
    hits = []
    for _ in range(500):
        out = step.observation({"observation.state": state, "observation.images.image": image})
        hits.append(out["observation.state"].isnan().all(-1))
        assert torch.equal(out["observation.images.image"].isnan().flatten(1).all(-1),
                           out["observation.images.image"].isnan().flatten(1).any(-1))  # whole frames
    assert abs(torch.stack(hits).float().mean().item() - 0.2) < 0.03
    assert step.counts["proprio"] == int(torch.stack(hits).sum())
    dropped = FaultInjectionStep(rate=1.0, mode="drop").observation({"observation.state": state})
    assert "observation.state" not in dropped
    with pytest.raises(ValueError, match="fault_rate"):
        FaultInjectionStep(rate=1.5)
    with pytest.raises(ValueError, match="fault_mode"):
        FaultInjectionStep(rate=0.1, mode="zero")


def test_front_end_marks_frames_it_cannot_encode(checkpoint):  # noqa: F811
    pipeline = PolicyProcessorPipeline.from_pretrained(checkpoint, config_filename="policy_preprocessor.json")
    step = next(s for s in pipeline.steps if isinstance(s, FrontendProcessorStep))
    frontend = FrozenFrontend(step.frontend().artefact, verbose=False)
    cameras = list(frontend.artefact.cameras)
    rng = np.random.default_rng(0)
    images = {k: torch.from_numpy(rng.random((3, 3, 128, 128), dtype=np.float32)) for k in cameras}
    spoiled = {k: v.clone() for k, v in images.items()}
    spoiled[cameras[1]][1, 0, 5, 5] = float("nan")
    batch = {**spoiled, "observation.state": torch.zeros(3, 9), "task": [SOUP] * 3}
    vision = pipeline(batch)[OBS_VISION_FEATURES]
    expected = frontend.encode_images(images)
    assert vision[1].isnan().all() and not vision[[0, 2]].isnan().any()
    torch.testing.assert_close(vision[[0, 2]], expected[[0, 2]], rtol=1e-5, atol=1e-5)
    step.reset()
    step.refresh_interval = 1  # encode every call
    pipeline(batch)  # an episode's first observation carries every trained camera (else it stops, test_rollout.py)
    missing = pipeline({cameras[0]: images[cameras[0]], "observation.state": torch.zeros(3, 9), "task": [SOUP] * 3})
    assert missing[OBS_VISION_FEATURES].isnan().all()
