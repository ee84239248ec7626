"""The `predvla` console command (`main`); one module per subcommand."""

from lerobot_predvla.cli.main import main

__all__ = ["main"]
