"""The compiled recurrence (`recurrence_backend="cpp"`) against the Python fast path it replaces.

The first test builds the C++ extension (~25-60 s once; cached in `recurrence_cpp.build_directory()` afterwards).
"""

import dataclasses
import subprocess
import sys

import pytest
import torch
from rollout_checks import outputs_and_gradients

from benchmarks.bench_core import (
    control_step_fn,
    control_stream,
    randomised_model,
    recorded_matmuls,
    training_data,
    training_loss,
)
from lerobot_predvla import PredVLAConfig
from lerobot_predvla.policies.predvla import recurrence_cpp
from lerobot_predvla.policies.predvla.error_regression import ErrorRegression

ABLATIONS = {
    "full": {}, "A2 no bottleneck": {"use_bottleneck": False}, "A3 no efference": {"use_efference_copy": False},
    "A2 + A3": {"use_bottleneck": False, "use_efference_copy": False},
}


def models(dtype: torch.dtype = torch.float32, **overrides) -> tuple:
    """The same randomised network with the Python loops and with the compiled ones."""
    config = PredVLAConfig(device="cpu", **overrides)
    return tuple(randomised_model(dataclasses.replace(config, recurrence_backend=backend)).to(dtype)
                 for backend in ("python", "cpp"))


DIE_MIDWAY_THROUGH_A_BUILD = """
import os, sys
from pathlib import Path
from lerobot_predvla.policies.predvla.recurrence_cpp import exclusive_build
directory = Path(sys.argv[1])
with exclusive_build(directory):
    (directory / "lock").touch()  # torch's FileBaton lock, taken at the start of a build
    os._exit(1)  # killed before torch removes it
"""


def test_a_build_killed_midway_does_not_block_the_next(tmp_path, caplog):
    directory = tmp_path / "predvla_recurrence"
    killed = subprocess.run([sys.executable, "-c", DIE_MIDWAY_THROUGH_A_BUILD, str(directory)], timeout=120)
    assert killed.returncode == 1 and (directory / "lock").exists()  # torch's FileBaton would wait on this forever
    with caplog.at_level("WARNING"), recurrence_cpp.exclusive_build(directory):
        assert not (directory / "lock").exists()
    assert "interrupted build" in caplog.text


def test_the_build_directory_is_per_python_and_torch_version(monkeypatch, tmp_path):
    monkeypatch.setenv("TORCH_EXTENSIONS_DIR", str(tmp_path))
    directory = recurrence_cpp.build_directory()
    assert directory.parent.parent == tmp_path and directory.name == recurrence_cpp.EXTENSION_NAME
    assert torch.__version__.split("+")[0] in directory.parent.name


def test_backend_is_validated():
    with pytest.raises(ValueError, match="recurrence_backend"):
        PredVLAConfig(device="cpu", recurrence_backend="cuda")


@pytest.mark.parametrize("overrides", ABLATIONS.values(), ids=ABLATIONS.keys())
@pytest.mark.parametrize("with_posteriors", [True, False], ids=["c_q", "priors on the fly"])
def test_every_output_and_gradient_matches_python_in_float64(overrides, with_posteriors):
    """Outputs, then gradients of a random projection of all of them with respect to every parameter, the
    posteriors and an extra A_bottom input: the compiled loops agree with the Python loops to 1e-10."""
    batch, steps = 3, 9
    results = []
    for model in models(torch.float64, **overrides):
        g = torch.Generator().manual_seed(1)
        language = torch.randn(batch, 64, generator=g, dtype=torch.float64)
        c_q = (0.3 * torch.randn(steps, batch, 256, generator=g, dtype=torch.float64)).requires_grad_(with_posteriors)
        extra_ab = torch.randn(steps, batch, 256, generator=g, dtype=torch.float64, requires_grad=True)
        posteriors = c_q if with_posteriors else None
        traj = model.rollout(model.initial_state(batch), model.language_term(language), posteriors, extra_ab=extra_ab)
        results.append(outputs_and_gradients(traj, model, extra_ab, posteriors))
    for cpp, python in zip(results[1], results[0], strict=True):
        torch.testing.assert_close(cpp, python, rtol=0, atol=1e-10)


@pytest.mark.parametrize("overrides", ABLATIONS.values(), ids=ABLATIONS.keys())
def test_training_loss_and_gradients_match_python_in_float32(overrides):
    results = []
    pair = models(**overrides)
    for model in pair:
        data = training_data(model.config, batch=3, steps=24)
        c_q = data["c_q"].clone().requires_grad_(True)
        loss = training_loss(model, model.rollout, data, c_q)
        results.append((loss, torch.autograd.grad(loss, [*model.parameters(), c_q])))
    (loss, grads), (cpp_loss, cpp_grads) = results
    assert abs(loss.item() - cpp_loss.item()) < 1e-5
    names = [name for name, _ in pair[0].named_parameters()] + ["posteriors"]
    for name, g, cpp in zip(names, grads, cpp_grads, strict=True):
        assert (g - cpp).abs().max() < 1e-5, name


@pytest.mark.parametrize("overrides", ABLATIONS.values(), ids=ABLATIONS.keys())
@pytest.mark.parametrize("dtype, tolerance", [(torch.float64, 1e-10), (torch.float32, 1e-5)])
def test_error_regression_actions_match_python(overrides, dtype, tolerance):
    """Sliding window included in float64; fp32 at the first control step only (Adam amplifies summation-order
    rounding, see tests/test_fast_path.py)."""
    steps = 6 if dtype == torch.float64 else 1
    actions = []
    for model in models(dtype, er_window=4, er_iterations=3, **overrides):
        language, obs = control_stream(model.config, batch=2, steps=steps)
        er = ErrorRegression(model)
        actions.append(torch.stack([er(language.to(dtype), v.to(dtype), q.to(dtype)) for v, q in obs]))
    assert (actions[0] - actions[1]).abs().max() < tolerance


@pytest.mark.parametrize("batch", [1, 4])
def test_same_matmuls_as_python(batch):
    """An error-regression control step issues the same matmuls on the same shapes and strides with either
    backend, so the benchmark's floor (which replays them) is the floor of both."""
    python, cpp = models(er_window=5, er_iterations=2)
    assert recorded_matmuls(control_step_fn(cpp, cpp.rollout, batch)) == recorded_matmuls(
        control_step_fn(python, python.rollout, batch)
    )


def test_other_devices_and_dtypes_are_refused():
    _, cpp = models()
    cpp = cpp.to(torch.bfloat16)
    with pytest.raises(ValueError, match="recurrence_backend='python'"):
        cpp.rollout(cpp.initial_state(1), cpp.language_term(torch.zeros(1, 64, dtype=torch.bfloat16)), steps=2)


def test_build_failure_names_the_flag(monkeypatch):
    def no_compiler(**kwargs):
        raise OSError("g++: not found")

    monkeypatch.setattr(torch.utils.cpp_extension, "load_inline", no_compiler)
    recurrence_cpp.extension.cache_clear()
    try:
        with pytest.raises(RuntimeError, match="recurrence_backend='cpp'.*g\\+\\+: not found"):
            recurrence_cpp.extension()
    finally:
        recurrence_cpp.extension.cache_clear()


def test_non_finite_values_propagate_as_in_python():
    """A non-finite posterior spreads through the states and actions as in the Python loops: error regression
    detects diverged environments by it (`ErrorRegression.infer`)."""
    outputs = []
    for model in models():
        c_q = 0.3 * torch.randn(6, 2, 256, generator=torch.Generator().manual_seed(4))
        c_q[2, 0, 5] = float("nan")
        traj = model.rollout(model.initial_state(2), model.language_term(torch.zeros(2, 64)), c_q)
        outputs.append([*traj.d, traj.q_hat, traj.a_hat])
    for python, cpp in zip(*outputs, strict=True):
        assert not python[:, 0].isfinite().all() and python[:, 1].isfinite().all()
        torch.testing.assert_close(cpp, python, rtol=0, atol=1e-5, equal_nan=True)


def test_auto_is_the_default_and_picks_the_loops_by_device_and_dtype():
    """"auto" runs the compiled loops on CPU float32/float64 where they build here, the Python loops otherwise;
    "python" (what configs saved before "auto" hold) keeps the Python loops."""
    assert PredVLAConfig(device="cpu").recurrence_backend == "auto"
    python = recurrence_cpp.python_recurrence
    assert recurrence_cpp.loops("python", torch.zeros(1)) is python
    assert recurrence_cpp.loops("auto", torch.zeros(1, dtype=torch.bfloat16)) is python
    if recurrence_cpp.missing_toolchain() is None:
        assert recurrence_cpp.loops("auto", torch.zeros(1)) is recurrence_cpp.recurrence
        assert recurrence_cpp.loops("auto", torch.zeros(1, dtype=torch.float64)) is recurrence_cpp.recurrence


def test_auto_falls_back_to_the_python_loops_with_the_compiler_hidden(monkeypatch, tmp_path, caplog):
    """Without a C++ compiler "auto" builds nothing, says why in one log line and acts as the Python loops do."""
    monkeypatch.setenv("CXX", str(tmp_path / "no-such-c++"))
    monkeypatch.setenv("TORCH_EXTENSIONS_DIR", str(tmp_path / "extensions"))
    recurrence_cpp.auto_uses_cpp.cache_clear()
    try:
        actions = []
        with caplog.at_level("INFO"):
            for backend in ("auto", "python"):
                model = randomised_model(PredVLAConfig(device="cpu", er_window=4, er_iterations=3,
                                                       recurrence_backend=backend))
                language, obs = control_stream(model.config, batch=2, steps=6)
                er = ErrorRegression(model)
                actions.append(torch.stack([er(language, v, q) for v, q in obs]))
        assert torch.equal(actions[0], actions[1])
        lines = [r.getMessage() for r in caplog.records if "recurrence_backend='auto'" in r.getMessage()]
        assert len(lines) == 1 and "no C++ compiler" in lines[0] and "no-such-c++" in lines[0]
        assert not (tmp_path / "extensions").exists()
    finally:
        recurrence_cpp.auto_uses_cpp.cache_clear()


def test_predvla_build_reports_a_missing_compiler_and_exits_0(monkeypatch, tmp_path, capsys):
    from lerobot_predvla.cli.main import main

    monkeypatch.setenv("CXX", str(tmp_path / "no-such-c++"))
    assert main(["build"]) == 0
    assert "no C++ compiler" in capsys.readouterr().out


@pytest.mark.skipif(recurrence_cpp.missing_toolchain() is not None, reason="no C++ toolchain")
def test_predvla_build_builds_once_ahead(capsys):
    from lerobot_predvla.cli.main import main

    assert main(["build"]) == 0
    assert f"ready in {recurrence_cpp.build_directory()}" in capsys.readouterr().out
