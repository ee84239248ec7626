"""Configuration of baselines B1, B3 and B4: causal BC-Transformer on PredVLA's cached inputs (Section 4.4)."""

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
    mean and scale per chunk step; this is the reading under which Table 4's differences are exact: B3 - B1 =
    7 x 17,990 and B4 - B1 = 15 x 17,990, with 17,990 = 257 x 70 per extra chunk step.

    Counts (ours / paper): chunk 1: 646,155 / 646,628 (-0.07%); chunk 8: 772,085 / 772,558 (-0.06%);
    chunk 16: 916,005 / 916,478 (-0.05%). The trunk reading (D=160, 2 layers, feed-forward 512, context 40,
    the error-regression window) is ours: no natural trunk we found gives B1's count exactly.

    Training samples one window per batch episode, ending at a uniformly drawn valid step, and scores the
    action NLL at every valid position (robomimic's BC-Transformer). Chunk targets past an episode's end repeat
    its last action. Acting keeps the last `context_length` steps; with chunks, the actions predicted for the
    current step by the last chunks are averaged by ACT's temporal ensembling.

    Args:
        embed_dim: Token width D (160).
        num_layers: Transformer encoder layers (2).
        num_heads: Attention heads (4).
        feedforward_dim: Hidden width of each layer's feed-forward block (512).
        dropout: Dropout inside the encoder layers (0.1).
        context_length: Steps the causal window covers, in training and at evaluation (40, PredVLA's W).
        chunk_size: Actions predicted per step: 1 (B1), 8 (B3) or 16 (B4).
        temporal_ensemble_coeff: ACT temporal-ensembling coefficient m of w_i = exp(-m i) (ACT's 0.01); used
            when chunk_size > 1.
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
