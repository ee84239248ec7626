"""Baselines B1, B3, B4: causal BC-Transformer with PredVLA's GMM head, optionally chunked (Section 4.5)."""

import torch
from lerobot.policies.act.modeling_act import ACTTemporalEnsembler
from torch import Tensor, nn

from lerobot_predvla.policies.bc_transformer.configuration_predvla_bc_transformer import (
    BC_TRANSFORMER_PAPER_PARAMETERS,
    PredVLABCTransformerConfig,
)
from lerobot_predvla.policies.common.action_head import GMMActionHead
from lerobot_predvla.policies.common.losses import masked_mean
from lerobot_predvla.policies.common.observation_policy import ObservationPolicy, observation_inputs


class PredVLABCTransformerPolicy(ObservationPolicy):
    """Causal Transformer over a sliding window of observations; chunked variants use ACT temporal ensembling."""

    config_class = PredVLABCTransformerConfig
    name = "predvla_bc_transformer"

    def __init__(
        self, config: PredVLABCTransformerConfig, dataset_stats: dict | None = None, dataset_meta=None, **kwargs
    ):
        super().__init__(config, dataset_stats, dataset_meta)
        self.paper_parameters = BC_TRANSFORMER_PAPER_PARAMETERS.get(config.chunk_size)
        d = config.embed_dim
        self.embed = nn.Linear(config.observation_dim, d)
        self.position = nn.Parameter(torch.zeros(config.context_length, d))
        nn.init.normal_(self.position, std=0.02)
        layer = nn.TransformerEncoderLayer(
            d, config.num_heads, config.feedforward_dim, config.dropout, batch_first=True, norm_first=True
        )
        self.encoder = nn.TransformerEncoder(layer, config.num_layers, enable_nested_tensor=False)
        self.norm = nn.LayerNorm(d)
        # One mixture over the whole chunk: shared weights, per-step means and scales (see the config).
        self.action_head = GMMActionHead(
            d, config.head_hidden_dim, config.chunk_size * config.action_dim, config.num_mixtures,
            config.min_action_scale,
        )
        self.log_parameter_count()
        self.reset()

    def encode(self, tokens: Tensor, valid: Tensor) -> Tensor:
        """Causal encoding of right-aligned windows (batch, context, 265) with `valid` (batch, context).

        A position attends to earlier valid positions and itself (so padded rows never see an empty set).
        """
        cfg = self.config
        n = tokens.shape[1]
        i = torch.arange(n, device=tokens.device)
        allowed = (i[None, :, None] >= i[None, None, :]) & (valid[:, None, :] | (i[:, None] == i[None, :]))
        mask = (~allowed).repeat_interleave(cfg.num_heads, dim=0)  # (batch * heads, query, key)
        x = self.embed(tokens) + self.position[cfg.context_length - n :]
        return self.norm(self.encoder(x, mask=mask))

    def sequence_loss(self, seq: dict[str, Tensor]) -> tuple[Tensor, dict[str, Tensor]]:
        cfg = self.config
        length = seq["valid"].sum(0)  # (batch,)
        steps, batch = seq["valid"].shape
        # One window per episode, ending at a uniformly drawn valid step.
        end = (torch.rand(batch, device=length.device) * length).long()
        window = end[:, None] - cfg.context_length + 1 + torch.arange(cfg.context_length, device=end.device)
        valid = window >= 0
        rows = window.clamp_min(0)
        cols = torch.arange(batch, device=end.device)[:, None]
        inputs = observation_inputs(seq["language"][:, None], seq["vision"][rows, cols], seq["state"][rows, cols])
        # Chunk targets a_t..a_{t+chunk-1}, the last action repeated past the episode's end.
        ahead = (rows[..., None] + torch.arange(cfg.chunk_size, device=end.device)).minimum((length - 1)[:, None, None])
        target = seq["action"][ahead, cols[..., None]].flatten(-2)
        params = self.action_head(self.encode(inputs, valid))
        loss = masked_mean(-GMMActionHead.distribution(*params).log_prob(target), valid)
        return loss, {"action_nll": loss}

    def reset(self) -> None:
        super().reset()
        self.window: list[Tensor] = []  # the last context_length input steps, each (batch, 265)
        self.ensembler = ACTTemporalEnsembler(self.config.temporal_ensemble_coeff, self.config.chunk_size)

    def chunk(self, language: Tensor, vision: Tensor, proprio: Tensor) -> Tensor:
        """Append this step to the window and decode the mode of its action chunk: (batch, chunk, action)."""
        self.window = [*self.window, observation_inputs(language, vision, proprio)][-self.config.context_length :]
        tokens = torch.stack(self.window, dim=1)
        logits, means, _ = self.action_head(self.encode(tokens, tokens.new_ones(tokens.shape[:2], dtype=torch.bool)))
        return GMMActionHead.mode(logits[:, -1], means[:, -1]).unflatten(-1, (self.config.chunk_size, -1))

    def act(self, language: Tensor, vision: Tensor, proprio: Tensor) -> Tensor:
        return self.ensembler.update(self.chunk(language, vision, proprio))

    @torch.no_grad()
    def predict_action_chunk(self, batch: dict[str, Tensor], **kwargs) -> Tensor:
        chunk = self.chunk(*self.observe(batch))
        return self.guard.safe_action(chunk.flatten(1)).unflatten(1, chunk.shape[1:])
