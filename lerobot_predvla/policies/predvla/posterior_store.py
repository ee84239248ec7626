"""Training posteriors c_q: one free variable per (episode, step, module) (Section 3.4).

The store is a parameter of the policy so that LeRobot's optimizer (own parameter group, own learning
rate, no weight decay), `.to(device)` and `--resume` treat it like any other trainable tensor. It is
written to its own file in training checkpoints and never to `model.safetensors` or the Hub.
"""

from pathlib import Path

import torch
from safetensors.torch import save_file
from torch import Tensor, nn

from lerobot_predvla.utils.safe_loading import check_tensors, read_safetensors

POSTERIOR_STORE_FILE = "posterior_store.safetensors"


class PosteriorStore(nn.Module):
    """Posteriors of shape (num_episodes, sequence_length, 4r), keyed by `episode_index` and step."""

    def __init__(self, num_episodes: int, sequence_length: int, posterior_dim: int):
        super().__init__()
        self.latents = nn.Parameter(torch.zeros(num_episodes, sequence_length, posterior_dim))

    def gather(self, episode_index: Tensor) -> Tensor:
        """Posteriors of the given episodes, time-major: (sequence_length, batch, 4r)."""
        if int(episode_index.max()) >= self.latents.shape[0] or int(episode_index.min()) < 0:
            raise IndexError(
                f"episode_index {episode_index.tolist()} outside the posterior store of "
                f"{self.latents.shape[0]} episodes; was the policy built from this dataset's metadata?"
            )
        return self.latents.index_select(0, episode_index).transpose(0, 1)

    def save(self, directory: Path) -> None:
        tmp = directory / f".{POSTERIOR_STORE_FILE}.tmp"
        save_file({"latents": self.latents.detach().cpu().contiguous()}, str(tmp))
        tmp.replace(directory / POSTERIOR_STORE_FILE)

    def read(self, directory: Path) -> Tensor | None:
        """The store saved beside a checkpoint's weights, checked (readable, finite, of this dataset's and
        config's shape: episodes, sequence_length, 4r) but not loaded; None when there is none."""
        path = Path(directory) / POSTERIOR_STORE_FILE
        if not path.is_file():
            return None
        tensors, _ = read_safetensors(path)
        check_tensors(path, tensors, {"latents": self.latents.detach().cpu()})
        return tensors["latents"]

    def assign(self, latents: Tensor) -> None:
        with torch.no_grad():
            self.latents.copy_(latents)

