"""Where `lerobot-train` puts a run's checkpoints (LeRobot's own directory names)."""

from pathlib import Path

from lerobot.utils.constants import CHECKPOINTS_DIR, LAST_CHECKPOINT_LINK, PRETRAINED_MODEL_DIR

REQUIRED_FILES = ("config.json", "model.safetensors")  # what makes a directory a saved policy


def last_pretrained(output_dir: Path) -> Path:
    """`OUTPUT_DIR/checkpoints/last/pretrained_model`: the latest saved policy of a `lerobot-train` run."""
    return Path(output_dir) / CHECKPOINTS_DIR / LAST_CHECKPOINT_LINK / PRETRAINED_MODEL_DIR


def find_pretrained(checkpoint: Path) -> Path | None:
    """The saved policy of `checkpoint`: the directory itself, its `pretrained_model/`, or None."""
    checkpoint = Path(checkpoint)
    for candidate in (checkpoint, checkpoint / PRETRAINED_MODEL_DIR):
        if all((candidate / name).is_file() for name in REQUIRED_FILES):
            return candidate
    return None
