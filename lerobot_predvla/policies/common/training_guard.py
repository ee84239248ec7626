"""Non-finite loss or gradient during `lerobot-train` (docs/reliability.md).

LeRobot 0.6.1's `update_policy` owns the loop: forward, backward, gradient clipping, optimizer step, and a
checkpoint every `--save_freq` steps. The policy sees two moments of it: the end of its own `forward`, where
the loss is checked, and, through a hook on that loss, the end of the backward pass, where every gradient
(network and the batch's training posteriors) is checked before the optimizer can use it.

With `on_nonfinite_training="stop"` (default) the run stops there with one line naming the step and the loss
terms, before a non-finite value reaches a weight, a posterior or a checkpoint. With "skip" the batch changes
nothing: the returned loss is a detached zero and every gradient is cleared, so the optimizer leaves all
parameters untouched (PyTorch optimizers skip parameters without gradients); the batch is counted and logged.
"""

import logging
import math
from collections.abc import Callable

import torch
from torch import Tensor, nn

# The stop message's fixed part: `predvla sweep` finds it in a training log to tell a diverged learning rate from
# a crash (sweep/lr_selection.py).
NONFINITE_STOP = "stopped before any weight, posterior or checkpoint became non-finite"


class NonFiniteTrainingError(SystemExit):
    """Stops training with one line (a `SystemExit`, so `lerobot-train` prints the message, no traceback)."""


class TrainingGuard:
    """Checks each training batch's loss and gradients; counts training steps as forward passes.

    Args:
        module: The policy; its parameters that require gradients are checked.
        mode: `on_nonfinite_training`, "stop" or "skip".
        name: Policy name used in messages.
        extra: Further (name, tensor) pairs whose `.grad` is checked and, when skipping, cleared alike
            (PredVLA: the batch's training posteriors, which are not parameters).
    """

    def __init__(self, module: nn.Module, mode: str, name: str,
                 extra: Callable[[], list[tuple[str, Tensor]]] | None = None):
        self.module, self.mode, self.name, self.extra = module, mode, name, extra
        self.step = 0  # training forward passes in this process (lerobot-train's step, counted from its start)
        self.skipped = 0
        self._terms: dict[str, float] = {}

    def check_loss(self, loss: Tensor, terms: dict[str, float]) -> Tensor:
        """The loss `forward` returns: unchanged if finite (its gradients are checked when backward ends),
        else stop, or a zero that trains nothing."""
        if not (torch.is_grad_enabled() and loss.requires_grad):
            return loss  # evaluation of the loss, not a training step
        self.step += 1
        self._terms = terms
        if math.isfinite(loss.item()) and all(math.isfinite(v) for v in terms.values()):
            loss.register_hook(self._check_gradients_after_backward)
            return loss
        self._fault("non-finite loss")
        return torch.zeros((), device=loss.device, requires_grad=True)  # backward reaches no parameter

    def _check_gradients_after_backward(self, grad: Tensor) -> Tensor:
        torch.autograd.Variable._execution_engine.queue_callback(self._check_gradients)
        return grad

    def _check_gradients(self) -> None:
        named = [*self.module.named_parameters(), *(self.extra() if self.extra is not None else [])]
        named = [(n, p) for n, p in named if p.grad is not None]
        if not named:
            return
        sums = torch.stack([p.grad.sum() for _, p in named])  # a NaN or infinity anywhere makes its sum so
        bad = [n for (n, _), finite in zip(named, torch.isfinite(sums).tolist(), strict=True) if not finite]
        if bad:
            self._fault(f"non-finite gradient of {', '.join(bad[:3])}{' ...' if len(bad) > 3 else ''}")
            for _, p in named:
                p.grad = None

    def _fault(self, what: str) -> None:
        terms = ", ".join(f"{k}={v:.6g}" for k, v in self._terms.items())
        line = f"{self.name}: {what} at training step {self.step} (loss terms: {terms})"
        if self.mode == "stop":
            raise NonFiniteTrainingError(
                f"{line}; {NONFINITE_STOP} (--policy.on_nonfinite_training=skip skips such batches)."
            )
        self.skipped += 1
        logging.warning("%s; batch skipped (%d so far).", line, self.skipped)
