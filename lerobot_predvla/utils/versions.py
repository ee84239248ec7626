"""Installed versions of the distributions a result depends on (recorded beside results and on model cards)."""

import importlib.metadata
import os
import platform
import subprocess
import sys
from pathlib import Path

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


def machine(cpuinfo: Path = Path("/proc/cpuinfo")) -> str:
    """The processor a result's wall times were measured on: model, logical CPUs, and whether it has the AVX-512
    bfloat16 instructions (machines of the same core count differ in speed; wall times compare only on one)."""
    model, flags = platform.processor() or platform.machine(), set()
    if cpuinfo.is_file():
        for line in cpuinfo.read_text(errors="replace").splitlines():
            key, _, value = line.partition(":")
            if key.strip() == "model name":
                model = value.strip()
            elif key.strip() == "flags":
                flags = set(value.split())
            if model and flags:
                break
    return f"{model}, {os.cpu_count()} logical CPUs, AVX-512 bf16: {'yes' if 'avx512_bf16' in flags else 'no'}"


def run_versions() -> dict[str, str]:
    """What a result file records of where it was made: package versions, the plugin's git commit when it runs from
    a checkout, the machine, and OMP_NUM_THREADS (a different thread count rounds error regression's sums
    differently, which can change an episode's outcome)."""
    found = {**package_versions(), "machine": machine(), "omp_num_threads": os.environ.get("OMP_NUM_THREADS", "unset")}
    try:
        commit = subprocess.run(
            ["git", "rev-parse", "HEAD"], capture_output=True, text=True, cwd=Path(__file__).parent, check=False
        ).stdout.strip()
        found["lerobot_predvla_git"] = commit or "unknown"
    except OSError:
        found["lerobot_predvla_git"] = "unknown"
    return found
