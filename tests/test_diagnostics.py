"""The diagnostics of `predvla inspect` that need no trained checkpoint (the rest: tests/test_inspect.py)."""

import pytest
import torch

from lerobot_predvla.policies.predvla.diagnostics import gripper_events, parse_er_variant


def test_gripper_events_find_the_close_and_the_release_after_it():
    gripper = torch.tensor([[-1, -1, 1, 1, -1, 1],     # closes at 2, reopens at 4 (then closes again)
                            [-1, 1, 1, 1, 1, 1],       # closes at 1, never reopens
                            [-1, -1, -1, -1, -1, -1],  # never closes
                            [-1, -1, -1, 1, 1, -1]],   # closes at 3; its reopening at 5 lies past its end
                           dtype=torch.float).T
    action = torch.cat([torch.zeros(*gripper.shape, 6), gripper[..., None]], dim=-1)  # (time, batch, 7)
    valid = torch.ones_like(gripper, dtype=torch.bool)
    valid[5:, 3] = False
    events = gripper_events(action, valid)
    assert torch.equal(events.isnan(), torch.tensor([[False, False], [False, True], [True, True], [False, True]]))
    assert torch.equal(events.nan_to_num(nan=-1), torch.tensor([[2.0, 4], [1, -1], [-1, -1], [3, -1]]))


def test_er_variants_parse_to_typed_settings_and_name_what_is_wrong():
    assert parse_er_variant("er_optimizer=gd, er_lr=0.05") == {"er_optimizer": "gd", "er_lr": 0.05}
    assert parse_er_variant("er_adam_state=carried,er_window=8") == {"er_adam_state": "carried", "er_window": 8}
    for text, message in (("er_optimizer=sgd", r"er_optimizer must be one of \('adam', 'gd'\), got 'sgd'"),
                          ("er_adam_state=kept", "er_adam_state must be one of"),
                          ("er_momentum=0.9", "KEY one of"),
                          ("er_window=eight", "er_window needs a int, got 'eight'"),
                          ("er_iterations=0", "er_iterations must be positive"),
                          ("er_lambda_v=-1", "er_lambda_v must not be negative")):
        with pytest.raises(ValueError, match=message):
            parse_er_variant(text)
