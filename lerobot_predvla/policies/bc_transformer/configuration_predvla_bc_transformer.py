"""Configuration of baselines B1, B3 and B4: causal BC-Transformer on PredVLA's cached inputs (Section 4.5)."""

from dataclasses import dataclass

from lerobot.configs import PreTrainedConfig

from lerobot_predvla.policies.common.observation_policy import ObservationPolicyConfig

# Table 4: B1 (chunk 1), B3 (chunk 8), B4 (chunk 16).
BC_TRANSFORMER_PAPER_PARAMETERS = {1: 646_628, 8: 772_558, 16: 916_478}


@PreTrainedConfig.register_subclass("predvla_bc_transformer")
@dataclass
class PredVLABCTransformerConfig(ObservationPolicyConfig):
    """Causal Transformer over the last `context_length` steps of [held vision; proprio; language] (265 per step).

    Architecture: bias-ful Linear(265, D) token embedding plus a learned position embedding (context_length x D),
    `num_layers` pre-norm torch TransformerEncoderLayers (D, `num_heads`, `feedforward_dim`, ReLU), a final
    LayerNorm, and PredVLA's GMM head Linear(D, 256)-ReLU-Linear(256, K (1 + 2 * 7 * chunk_size)) at every
    position. With action chunks the K mixture weights are shared by the whole chunk and each component has a
    mean and scale per chunk step: the reading under which Table 4's differences between B1, B3 and B4 are exact.
    The paper gives only the parameter counts; the trunk's sizes are ours, within 0.07% of them (docs/paper.md).

    Training samples one window per batch episode, ending at a uniformly drawn valid step, and scores the
    action NLL at every valid position (robomimic's BC-Transformer). Chunk targets past an episode's end repeat
    its last action. Acting keeps the last `context_length` steps; with chunks, the actions predicted for the
    current step by the last chunks are averaged by ACT's temporal ensembling (Section 4.5).

    Args:
        embed_dim: Token width D (default 160, ours; Table 4 gives only the parameter count).
        num_layers: Transformer encoder layers (default 2, ours).
        num_heads: Attention heads (default 4, ours); must divide `embed_dim`.
        feedforward_dim: Hidden width of each layer's feed-forward block (default 512, ours).
        dropout: Dropout probability inside the encoder layers (default 0.1, ours).
        context_length: Steps the causal window covers, in training and at evaluation (default 40, ours: PredVLA's
            error-regression window W of Table 2).
        chunk_size: Actions predicted per step: 1 (default, B1), 8 (B3) or 16 (B4) (Section 4.5; Table 4).
        temporal_ensemble_coeff: Coefficient m of ACT's temporal-ensembling weights w_i = exp(-m i), used when
            `chunk_size` > 1 (default 0.01, ACT's; Section 4.5 names ACT-style ensembling without a value).
    """

    embed_dim: int = 160
    num_layers: int = 2
    num_heads: int = 4
    feedforward_dim: int = 512
    dropout: float = 0.1
    context_length: int = 40
    chunk_size: int = 1
    temporal_ensemble_coeff: float = 0.01

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.embed_dim % self.num_heads:
            raise ValueError(f"`embed_dim` ({self.embed_dim}) must be divisible by `num_heads` ({self.num_heads}).")
        if self.context_length < 1 or self.chunk_size < 1:
            raise ValueError(
                f"`context_length` and `chunk_size` must be >= 1, got {self.context_length} and {self.chunk_size}."
            )
