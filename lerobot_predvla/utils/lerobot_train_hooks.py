"""The plugin's one interposition into `lerobot-train`: atomic checkpoints and one training per output folder.

LeRobot 0.6.1 offers a policy no hook around checkpoint writing nor any hook that sees the output folder, so
when `lerobot-train` imports the plugin (`register_third_party_plugins`, before `train()` runs) this module
replaces three names in the namespace of `lerobot.scripts.lerobot_train` only; LeRobot's source and every
other caller of these functions are left as they are:

- `save_checkpoint`: LeRobot's own, writing into a staging folder that is renamed into place once complete
  and given SHA-256 manifests (`utils/checkpoints.py`, `utils/manifest.py`);
- `update_last_checkpoint`: a new `last` link renamed over the old one instead of unlink-then-create;
- `make_train_eval_datasets` (the first call that receives the resolved train config): LeRobot's own, after
  taking the output folder's lock (`utils/run_lock.py`) when the folder exists (a resume); a fresh run takes
  it at its first checkpoint, when LeRobot creates the folder.

`PREDVLA_LEROBOT_TRAIN_HOOKS=0` leaves `lerobot-train` exactly as LeRobot ships it.
"""

import functools
import logging
import os
import sys
from pathlib import Path

from lerobot.utils.constants import CHECKPOINTS_DIR

from lerobot_predvla.utils.checkpoints import (
    remove_leftovers,
    save_checkpoint_atomically,
    update_last_checkpoint_atomically,
)
from lerobot_predvla.utils.run_lock import lock_output_dir

LEROBOT_TRAIN = "lerobot.scripts.lerobot_train"
HOOKS_ENV = "PREDVLA_LEROBOT_TRAIN_HOOKS"
_INSTALLED = "_predvla_hooks_installed"


def _is_main_process() -> bool:
    return int(os.environ.get("RANK", "0")) == 0  # torchrun / accelerate launch set RANK per process


def hold_output_dir(output_dir: Path) -> None:
    """Take the run's lock (once per process) and clear what killed checkpoint writes left behind."""
    output_dir = Path(output_dir)
    lock_output_dir(output_dir)
    if (output_dir / CHECKPOINTS_DIR).is_dir():
        remove_leftovers(output_dir / CHECKPOINTS_DIR)


def _lerobot_train_modules() -> list:
    main = sys.modules.get("__main__")
    found = [sys.modules.get(LEROBOT_TRAIN)]
    if main is not None and getattr(getattr(main, "__spec__", None), "name", None) == LEROBOT_TRAIN:
        found.append(main)  # python -m lerobot.scripts.lerobot_train
    return [m for m in found if m is not None and not getattr(m, _INSTALLED, False)]


def install_lerobot_train_hooks() -> bool:
    """Replace the three names in a loaded `lerobot.scripts.lerobot_train`; True if it was done now."""
    if os.environ.get(HOOKS_ENV, "1") == "0":
        return False
    modules = _lerobot_train_modules()
    for module in modules:
        lerobot_save, lerobot_datasets = module.save_checkpoint, module.make_train_eval_datasets

        @functools.wraps(lerobot_save)
        def save_checkpoint(checkpoint_dir, *args, _save=lerobot_save, **kwargs):
            hold_output_dir(Path(checkpoint_dir).parent.parent)  # OUTPUT_DIR/checkpoints/<step>
            save_checkpoint_atomically(_save, checkpoint_dir, *args, **kwargs)

        @functools.wraps(lerobot_datasets)
        def make_train_eval_datasets(cfg, *args, _make=lerobot_datasets, **kwargs):
            if _is_main_process() and cfg.output_dir is not None and Path(cfg.output_dir).is_dir():
                hold_output_dir(Path(cfg.output_dir))
            return _make(cfg, *args, **kwargs)

        module.save_checkpoint = save_checkpoint
        module.update_last_checkpoint = update_last_checkpoint_atomically
        module.make_train_eval_datasets = make_train_eval_datasets
        setattr(module, _INSTALLED, True)
        logging.debug("PredVLA: atomic checkpoints and the output-folder lock installed in %s", module.__name__)
    return bool(modules)
