"""Configuration of baseline B2, BC-RNN (LSTM), on PredVLA's cached inputs (Section 4.4, Table 4)."""

from dataclasses import dataclass

from lerobot.configs import PreTrainedConfig

from lerobot_predvla.policies.common.observation_policy import ObservationPolicyConfig

BC_RNN_PAPER_PARAMETERS = 674_276  # Table 4, B2


@PreTrainedConfig.register_subclass("predvla_bc_rnn")
@dataclass
class PredVLABCRNNConfig(ObservationPolicyConfig):
    """BC-RNN (robomimic-style): an LSTM over [held vision 192; proprio 9; language 64] with PredVLA's GMM head.

    Parameter reading: torch `nn.LSTM(265, 272)` (one layer, both bias vectors, zero initial state) and the
    two-layer GMM head Linear(272, 256)-ReLU-Linear(256, 75) give 675,595 trainable parameters, 1,319 (+0.20%)
    above the paper's 674,276 (width 271: 672,099, -0.32%). No natural reading we found (one or more layers,
    one or two bias vectors, learnable initial states, input embedding) is exact. Fields of the base class are
    documented in `ObservationPolicyConfig`.

    Args:
        hidden_dim: LSTM state size (272: the closest to Table 4's count).
        num_layers: Stacked LSTM layers (1).
    """

    hidden_dim: int = 272
    num_layers: int = 1
