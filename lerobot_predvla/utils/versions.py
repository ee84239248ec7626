"""Installed versions of the distributions a result depends on (recorded beside results and on model cards)."""

import importlib.metadata
import sys

NOT_INSTALLED = "not installed"
RUN_DISTRIBUTIONS = ("lerobot", "torch", "lerobot_policy_predvla", "hf-libero")


def package_version(distribution: str) -> str:
    try:
        return importlib.metadata.version(distribution)
    except importlib.metadata.PackageNotFoundError:
        return NOT_INSTALLED


def package_versions(distributions: tuple[str, ...] = RUN_DISTRIBUTIONS) -> dict[str, str]:
    """{"python": ..., distribution: version or "not installed"}."""
    return {"python": sys.version.split()[0], **{d: package_version(d) for d in distributions}}
