"""Baseline B2, BC-RNN: an LSTM policy on PredVLA's cached inputs with its GMM action head (Section 4.5)."""

from torch import Tensor, nn

from lerobot_predvla.policies.bc_rnn.configuration_predvla_bc_rnn import BC_RNN_PAPER_PARAMETERS, PredVLABCRNNConfig
from lerobot_predvla.policies.common.action_head import GMMActionHead
from lerobot_predvla.policies.common.losses import masked_mean
from lerobot_predvla.policies.common.observation_policy import ObservationPolicy, observation_inputs


class PredVLABCRNNPolicy(ObservationPolicy):
    """LSTM over whole training episodes (BPTT), stepped once per control step at evaluation."""

    config_class = PredVLABCRNNConfig
    name = "predvla_bc_rnn"
    paper_parameters = BC_RNN_PAPER_PARAMETERS

    def __init__(self, config: PredVLABCRNNConfig, dataset_stats: dict | None = None, dataset_meta=None, **kwargs):
        super().__init__(config, dataset_stats, dataset_meta)
        self.lstm = nn.LSTM(config.observation_dim, config.hidden_dim, config.num_layers)
        self.action_head = GMMActionHead(
            config.hidden_dim, config.head_hidden_dim, config.action_dim, config.num_mixtures, config.min_action_scale
        )
        self.log_parameter_count()
        self.reset()

    def sequence_loss(self, seq: dict[str, Tensor]) -> tuple[Tensor, dict[str, Tensor]]:
        out, _ = self.lstm(observation_inputs(seq["language"], seq["vision"], seq["state"]))
        nll = -GMMActionHead.distribution(*self.action_head(out)).log_prob(seq["action"])
        loss = masked_mean(nll, seq["valid"])
        return loss, {"action_nll": loss}

    def reset(self) -> None:
        super().reset()
        self.hidden: tuple[Tensor, Tensor] | None = None  # LSTM (h, c); None: zeros at the episode start

    def act(self, language: Tensor, vision: Tensor, proprio: Tensor) -> Tensor:
        out, self.hidden = self.lstm(observation_inputs(language, vision, proprio)[None], self.hidden)
        logits, means, _ = self.action_head(out[0])
        return GMMActionHead.mode(logits, means)
