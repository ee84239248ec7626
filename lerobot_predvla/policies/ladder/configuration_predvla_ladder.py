"""Configuration of the ladder rungs L2-L5 and side branch L2b from PredVLA to BC-RNN (Section 4.6, Table 5).

L0 is PredVLA itself, L1 and the inference-time ablations are PredVLAConfig fields (`er_iterations=0`), and
L6 is the BC-RNN baseline (`predvla_bc_rnn`); see configs/policy/.
"""

from dataclasses import dataclass

from lerobot.configs import PreTrainedConfig

from lerobot_predvla.policies.predvla.configuration_predvla import PREDVLA_PAPER_PARAMETERS, PredVLAConfig

LADDER_RUNGS = ("L2", "L2b", "L3", "L4", "L5")
LADDER_WIDTHS = {"L2": 256, "L2b": 256, "L3": 301, "L4": 301, "L5": 142}  # Section 4.6: d per rung
LADDER_PAPER_PARAMETERS = {"L2": PREDVLA_PAPER_PARAMETERS, "L2b": 724_884, "L3": 674_560, "L4": 674_560, "L5": 676_928}
PREDICTIVE_RUNGS = ("L2", "L2b")  # the network still predicts vision and proprioception


@PreTrainedConfig.register_subclass("predvla_ladder")
@dataclass
class PredVLALadderConfig(PredVLAConfig):
    """One rung of the mechanism ladder; every other field is PredVLAConfig's, with the same defaults.

    Rungs (each keeps the previous rung's changes; trained 30,000 steps at lr 6e-5 like PredVLA):

    - L2, no free variables or latent free-energy inference: PredVLA's network (d = 256, 675,732 parameters)
      with every posterior fixed at its prior, computed on the fly; trained on the visual and proprioceptive
      prediction errors and the action NLL; no posterior store, no complexity term, no error regression.
    - L2b, L2 plus direct visual input: a bias-free Linear(192, 256) W_vis of the latest refreshed visual
      features is added to A_bottom's pre-activation: 675,732 + 49,152 = 724,884 parameters (exact).
    - L3, no sensory prediction: no free variables, priors or visual decoder; observations enter the dynamics
      directly: V receives [v_t (held between refreshes); q_t] besides its top-down input and the efference copy
      [a_hat_{t-1}; q_hat_{t-1}], A_bottom receives q_t. Each module is one bias-ful Linear on [d^l_{t-1};
      inputs] with a learnable initial state; T keeps W_lang l, A_top the bottleneck, A_bottom the q head (the
      efference copy's source, now without a prediction loss) and the GMM head. Trained on the action NLL alone.
      d = 301 gives 674,560 parameters (exact).
    - L4, L3 with every tau = 1 (674,560, exact).
    - L5, L4 with each module's leaky-tanh update replaced by an LSTM cell (one bias per gate, learnable initial
      h and c), same inputs and connections: d = 142 gives 676,928 parameters (exact).

    The same reading of L3 and L5 gives both of the paper's counts exactly, which is why we chose it.
    Fields `posterior_lr`, `complexity_weights` and the `er_*` fields have no effect on any rung (no posteriors,
    no error regression); `lambda_v` and `lambda_q` apply to L2 and L2b only.

    Args:
        rung: The rung, "L2" (default), "L2b", "L3", "L4" or "L5" (Section 4.6; Table 5).
        width: Recurrent width d of V, A_top and A_bottom; T keeps `module_dims[0]` = 64. None (default): the
            paper's width for the rung (Section 4.6: 256, 256, 301, 301, 142); `module_dims` is set from it.
    """

    rung: str = "L2"
    width: int | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.rung not in LADDER_RUNGS:
            raise ValueError(f"`rung` must be one of {LADDER_RUNGS}, got {self.rung!r}.")
        if self.width is None:
            self.width = LADDER_WIDTHS[self.rung]
        self.module_dims = (self.module_dims[0], self.width, self.width, self.width)
        if self.rung in ("L4", "L5"):
            self.tau = (1.0, 1.0, 1.0, 1.0)  # Section 4.6: no temporal hierarchy from L4 on

    @property
    def predictive(self) -> bool:
        """L2 and L2b keep PredVLA's predictive network; L3-L5 take observations as inputs."""
        return self.rung in PREDICTIVE_RUNGS
