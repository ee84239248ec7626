"""The fused recurrence's per-step loops compiled in C++ (`PredVLAConfig.recurrence_backend`, "auto" or "cpp").

Same equations, buffers, matmuls and gradients as `recurrence.python_forward` and `python_backward` (Eqs. 3-6 and
their hand-written BPTT): the matmuls are the same ATen calls on the same operands (so the benchmark's floor, which
replays recorded matmuls, is the same), while everything between them (tanh, the leaky integration, the
concatenations, ReLU, the GMM mode, the BPTT's elementwise products) runs as one plain C++ loop per module and step
instead of ~21 dispatched ATen ops, below autograd's dispatch keys (the autograd node is `recurrence.Recurrence` on
`CPP_KERNELS`). At batch 1 error regression is dominated by those dispatches (docs/speed.md). The weight
gradients after the loop are the Python path's (`recurrence.weight_gradients`).

The extension's source is `recurrence.cpp` beside this module (package data). It is compiled with
`torch.utils.cpp_extension.load_inline` (g++ and ninja needed; ~30 s on 2 cores), once per Python and torch version
(`build_directory()`): ahead of any rollout by `predvla build` (which `make install` runs), else by the first
rollout, with a log line. Later processes load it in ~0.1 s. Builds are serialised by an OS
file lock that dies with its holder, so an interrupted build never blocks the next one (`exclusive_build`). It runs on
CPU tensors in float32 or float64. tanh uses glibc's vector kernels (libmvec, AVX2, <= 4 ulp) where the CPU and C
library have them, else std::tanh; the log line names which.

`loops(backend, tensor)` picks the implementation: "cpp" always the compiled loops (an error naming the flag if they
cannot be built); "python" always the Python loops; "auto" (the default) the compiled loops on CPU float32/float64
where they build here, else the Python loops, with one log line saying why (`auto_uses_cpp`).
"""

import importlib.resources
import logging
import os
import shutil
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from functools import cache
from pathlib import Path
from types import ModuleType

import torch
from torch import Tensor

from lerobot_predvla.policies.predvla.recurrence import (
    PYTHON_KERNELS,
    FusedWeights,
    Kernels,
    Meta,
    Recurrence,
    pack_outputs,
    unpack_inputs,
    weight_gradients,
)
from lerobot_predvla.policies.predvla.recurrence import recurrence as python_recurrence

# The C++ source (package data, pyproject.toml), passed to load_inline as text: the same text keeps an existing build.
SOURCE_FILE = importlib.resources.files("lerobot_predvla.policies.predvla") / "recurrence.cpp"
EXTENSION_NAME = "predvla_recurrence"
DTYPES = (torch.float32, torch.float64)  # what the compiled loops run on (CPU tensors)


def build_directory() -> Path:
    """Where the extension is built: under `$TORCH_EXTENSIONS_DIR` (default `~/.cache/torch_extensions`), one folder
    per Python and torch version (torch's own default separates Python versions only, not torch's ABI)."""
    root = Path(os.environ.get("TORCH_EXTENSIONS_DIR") or Path.home() / ".cache" / "torch_extensions")
    python = f"py{sys.version_info.major}{sys.version_info.minor}"
    return root / f"{python}_torch{torch.__version__.replace('+', '_')}" / EXTENSION_NAME


@contextmanager
def exclusive_build(directory: Path) -> Iterator[None]:
    """Holds an OS lock on `directory` while one process builds or loads the extension there.

    torch's own lock (`<directory>/lock`, a `FileBaton`) is a plain file: a build killed midway leaves it behind and
    every later build waits on it forever. `flock` is released by the OS when its holder dies, so the holder is the
    only builder, and a `lock` file it finds was left by an interrupted build: it is removed, with a warning.
    """
    import fcntl  # POSIX only, like the g++ toolchain the extension needs

    directory.mkdir(parents=True, exist_ok=True)
    with open(directory / "predvla_build.flock", "w") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        stale = directory / "lock"
        if stale.exists():
            logging.warning("PredVLA: removing %s, left by an interrupted build of the C++ recurrence", stale)
            stale.unlink()
        yield


def _ninja_on_path() -> None:
    """torch runs `ninja` from PATH; pip's ninja (the `test` extra) sits beside this interpreter, which an unactivated
    virtual environment leaves off PATH."""
    here = os.path.dirname(sys.executable)
    if here not in os.environ.get("PATH", "").split(os.pathsep):
        os.environ["PATH"] = os.pathsep.join(filter(None, (here, os.environ.get("PATH"))))


def missing_toolchain() -> str | None:
    """Why the extension cannot be built here (no C++ compiler, no ninja), or None."""
    from torch.utils import cpp_extension  # imported on use: it imports setuptools and probes for CUDA

    _ninja_on_path()
    compiler = cpp_extension.get_cxx_compiler()  # $CXX, else c++
    if shutil.which(compiler) is None:
        return f"no C++ compiler ({compiler!r} not found; install g++ or set $CXX)"
    if not cpp_extension.is_ninja_available():
        return "ninja not found (`pip install ninja`)"
    return None


@cache
def extension() -> ModuleType:
    """Builds (first call in a fresh extension directory) or loads the compiled loops; logged once."""
    from torch.utils import cpp_extension

    _ninja_on_path()
    start = time.perf_counter()
    directory = build_directory()
    if not any(directory.glob(f"{EXTENSION_NAME}*.so")):
        logging.info(
            "PredVLA: compiling the C++ recurrence into %s (once per Python and torch version, ~30 s on 2 cores; "
            "`predvla build` does it ahead)", directory,
        )
    try:
        with exclusive_build(directory):
            module = cpp_extension.load_inline(
                name=EXTENSION_NAME, cpp_sources=SOURCE_FILE.read_text(),
                functions=["forward", "backward", "tanh_kernel"], extra_cflags=["-O3"], build_directory=str(directory),
            )
    except Exception as error:  # the compiler's, ninja's or the loader's error, whichever failed
        raise RuntimeError(
            "PredVLAConfig.recurrence_backend='cpp' needs the C++ recurrence built with "
            "torch.utils.cpp_extension.load_inline, which needs a C++ compiler (g++) and ninja "
            "(`pip install ninja`); it failed: "
            f"{error}. Install them or use recurrence_backend='python' (same results)."
        ) from error
    logging.info(
        "PredVLA: C++ recurrence ready in %.1f s (%s), tanh: %s",
        time.perf_counter() - start, directory, module.tanh_kernel(),
    )
    return module


@cache
def auto_uses_cpp() -> bool:
    """Whether recurrence_backend='auto' runs the compiled loops in this process: True once they are built or
    loaded; else False, and one log line says why (no compiler, no ninja, or the build's error)."""
    reason = missing_toolchain()
    if reason is None:
        try:
            extension()
            return True
        except RuntimeError as error:
            reason = f"the build failed: {error.__cause__}"
    logging.warning(
        "PredVLA: recurrence_backend='auto' runs the Python loops (same results; error regression ~1.6x slower on "
        "CPU): %s", reason,
    )
    return False


def loops(backend: str, like: Tensor) -> Callable[..., tuple]:
    """The recurrence implementation `backend` selects for tensors like `like` (see the module docstring)."""
    compiled = backend == "cpp" or (
        backend == "auto" and like.device.type == "cpu" and like.dtype in DTYPES and auto_uses_cpp()
    )
    return recurrence if compiled else python_recurrence


def kernels(backend: str, like: Tensor) -> Kernels:
    """The loops `loops(backend, like)` runs, as `Kernels` (for `recurrence.shared_acting_chain`)."""
    return CPP_KERNELS if loops(backend, like) is recurrence else PYTHON_KERNELS


def cpp_forward(meta: Meta, *args: Tensor) -> tuple[tuple[Tensor, ...], tuple[Tensor, ...]]:
    """The compiled loops' forward: the outputs and the buffers its backward reads (batch on dim 1)."""
    p, h, d, a0, q0, w = unpack_inputs(args)
    outs = extension().forward(
        list(meta.alpha), meta.efference, meta.num_mixtures, meta.action_dim, meta.proprio_dim, p, h, d, a0, q0,
        [w.w_t.t(), w.w_v.t(), w.w_at.t(), w.w_ab.t()], None if w.w_va is None else w.w_va.t(),
        w.w1.t(), w.b1, w.w2.t(), w.b2,
    )
    dbuf, gbuf, inbuf, (y1, out, abuf, index), h_final = outs[0:4], outs[4:8], outs[8:11], outs[11:15], outs[15:19]
    return pack_outputs(meta, dbuf, out, abuf, y1, h_final), (*dbuf, *gbuf, *inbuf, y1, abuf, index)


def cpp_backward(
    meta: Meta, buffers: tuple[Tensor, ...], w: FusedWeights, grads: tuple[Tensor | None, ...],
    needs_w: tuple[bool, ...],
) -> tuple[Tensor | None, ...]:
    """The compiled loops' backward: the gradients of `unpack_inputs`' flat inputs from those of the outputs."""
    dbuf, gbuf, inbuf, (y1, abuf, index) = buffers[0:4], buffers[4:8], buffers[8:11], buffers[11:14]
    outs = extension().backward(
        list(meta.alpha), meta.efference, meta.num_mixtures, meta.action_dim, meta.proprio_dim,
        list(dbuf), list(gbuf), y1, abuf, index, [w.w_t, w.w_v, w.w_at, w.w_ab], w.w_va, w.w1, w.w2,
        list(grads[0:4]), grads[4], grads[5], grads[6], list(grads[7:11]),
    )
    gx, (gout, gy1), gh, carry = outs[0:4], outs[4:6], outs[6:10], outs[10:14]
    grad_a0, grad_q0 = outs[14:16] if meta.efference else (None, None)
    grad_w = weight_gradients(needs_w, w, list(gx), list(dbuf), list(inbuf), y1, gy1, gout)
    return (*gx, *gh, *carry, grad_a0, grad_q0, *grad_w)


CPP_KERNELS = Kernels(cpp_forward, cpp_backward)


def recurrence(
    meta: Meta, p: list[Tensor], h: tuple[Tensor, ...], d: tuple[Tensor, ...], a: Tensor, q: Tensor, w: FusedWeights
) -> tuple[list[Tensor], Tensor, Tensor, Tensor, tuple[Tensor, ...]]:
    """`recurrence.recurrence` with the compiled loops (CPU tensors, float32 or float64)."""
    if a.device.type != "cpu" or a.dtype not in DTYPES:
        raise ValueError(
            f"PredVLAConfig.recurrence_backend='cpp' runs on CPU tensors in float32 or float64, got {a.device} "
            f"{a.dtype}; use recurrence_backend='python' on other devices and dtypes."
        )
    outs = Recurrence.apply(CPP_KERNELS, meta, *p, *h, *d, a, q, *w)
    return list(outs[0:4]), outs[4], outs[5], outs[6], tuple(outs[7:11])
