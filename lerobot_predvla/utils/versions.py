"""Installed versions of the distributions a result depends on (recorded beside results and on model cards)."""

import importlib.metadata
import os
import platform
import subprocess
import sys
from pathlib import Path

import numpy as np
import threadpoolctl

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


def _cpuinfo_value(key: str, cpuinfo: Path) -> str | None:
    """The first `key : value` line's value in /proc/cpuinfo; None where the file or the key is missing."""
    if cpuinfo.is_file():
        for line in cpuinfo.read_text(errors="replace").splitlines():
            name, _, value = line.partition(":")
            if name.strip() == key:
                return value.strip()
    return None


def cpu_flags(cpuinfo: Path = Path("/proc/cpuinfo")) -> set[str]:
    """The processor's instruction-set flags (empty where /proc/cpuinfo is missing)."""
    return set((_cpuinfo_value("flags", cpuinfo) or "").split())


def machine(cpuinfo: Path = Path("/proc/cpuinfo")) -> str:
    """The processor a result's wall times were measured on: model, logical CPUs, and whether it has the AVX-512
    bfloat16 instructions (machines of the same core count differ in speed; wall times compare only on one)."""
    model = _cpuinfo_value("model name", cpuinfo) or platform.processor() or platform.machine()
    bf16 = "avx512_bf16" in cpu_flags(cpuinfo)
    return f"{model}, {os.cpu_count()} logical CPUs, AVX-512 bf16: {'yes' if bf16 else 'no'}"


def openblas_coretype() -> str:
    """The kernel set (e.g. "SkylakeX", "Haswell") that numpy's OpenBLAS picked for this processor; "none" when no
    OpenBLAS is loaded. robosuite's controller solves with numpy, and the kernel sets round differently, so a
    simulated demonstration regenerates bit for bit only under the one it was made under: `OPENBLAS_CORETYPE=NAME`
    (set before Python starts) pins it on any processor that has its instructions."""
    openblas = [lib for lib in threadpoolctl.threadpool_info() if lib.get("internal_api") == "openblas"]
    # numpy's own copy (wheels put it in numpy.libs) before another package's, such as scipy's
    openblas.sort(key=lambda lib: Path(np.__file__).parent.name not in Path(lib["filepath"]).parent.name)
    if openblas:
        return str(openblas[0].get("architecture"))
    return "none"


def run_versions() -> dict[str, str]:
    """What a result file records of where it was made: package versions, the plugin's git commit when it runs from
    a checkout, the machine, and OMP_NUM_THREADS (a different thread count rounds error regression's sums
    differently, which can change an episode's outcome) and the OpenBLAS kernel set (`openblas_coretype`)."""
    found = {**package_versions(), "machine": machine(), "omp_num_threads": os.environ.get("OMP_NUM_THREADS", "unset"),
             "openblas_coretype": openblas_coretype()}
    try:
        commit = subprocess.run(
            ["git", "rev-parse", "HEAD"], capture_output=True, text=True, cwd=Path(__file__).parent, check=False
        ).stdout.strip()
        found["lerobot_predvla_git"] = commit or "unknown"
    except OSError:
        found["lerobot_predvla_git"] = "unknown"
    return found
