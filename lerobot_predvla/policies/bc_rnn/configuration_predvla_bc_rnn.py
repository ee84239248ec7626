"""Configuration of baseline B2, BC-RNN (LSTM), on PredVLA's cached inputs (Section 4.5, Table 4)."""

from dataclasses import dataclass

from lerobot.configs import PreTrainedConfig

from lerobot_predvla.policies.common.observation_policy import ObservationPolicyConfig

BC_RNN_PAPER_PARAMETERS = 674_276  # Table 4, B2


@PreTrainedConfig.register_subclass("predvla_bc_rnn")
@dataclass
class PredVLABCRNNConfig(ObservationPolicyConfig):
    """BC-RNN (robomimic-style): an LSTM over [held vision 192; proprio 9; language 64] with PredVLA's GMM head.

    The paper gives B2's parameter count (Table 4: 674,276) but not its layout. Ours is torch's `nn.LSTM(265, 272)`
    (one layer, both bias vectors, zero initial state) and the GMM head Linear(272, 256)-ReLU-Linear(256, 75):
    675,595 trainable parameters, +0.20% (docs/paper.md). Fields of the base class are documented in
    `ObservationPolicyConfig`.

    Args:
        hidden_dim: LSTM state size (default 272, our choice: the width closest to Table 4's count).
        num_layers: Stacked LSTM layers (default 1, our choice; the paper does not give it).
    """

    hidden_dim: int = 272
    num_layers: int = 1
