"""The data stages of a sweep: a suite's dataset made before its first training, from the sweep file's `data`
entry (`predvla demos`, `predvla fit-frontend`, `predvla convert`) and its `train_root` copy without camera frames
(`predvla features-only`). Each stage is skipped once its output exists, so a killed sweep resumes. A front end
shared by several suites (`data.<suite>.frontend_from`) is fitted in the data stage of the first of them that
runs, after every one of their demonstrations is made; the others then only convert."""

import json
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from itertools import groupby
from pathlib import Path

from lerobot_predvla.frontend.artefact import METADATA_FILE
from lerobot_predvla.lerobot_commands import PREDVLA
from lerobot_predvla.sims.libero.env import num_tasks, task_spec
from lerobot_predvla.sims.libero.hdf5_layout import task_file
from lerobot_predvla.sweep.data_spec import DataSpec, fitted_suites
from lerobot_predvla.sweep.layout import data_stages_path
from lerobot_predvla.sweep.workspace import Workspace, describe_exit
from lerobot_predvla.utils.io import atomic_write_json
from lerobot_predvla.utils.versions import openblas_coretype


def style_args(spec: DataSpec) -> list[str]:
    """`predvla demos` flags of the demonstration style and the placement spread; none for the scripted style on
    LIBERO's placements, so the commands of earlier sweeps stay as they were recorded."""
    args = ["--style", spec.style, "--diversity", str(spec.diversity)] if spec.style != "scripted" else []
    return args + (["--placement-spread-cm", str(spec.placement_spread)] if spec.placement_spread > 0 else [])


class DataStages(Workspace):
    """Makes the datasets a sweep trains on."""

    def data_commands(self, suite: str) -> list[tuple[str, list[str]]]:
        """(stage, command) still to run to make `suite`'s datasets: its `root` from the `data` entry, then its
        `train_root` copy without camera frames; empty when they exist (or nothing says how to make them)."""
        entry = self.sweep.settings.datasets[suite]
        commands = self.source_data_commands(suite)
        train_root = self.train_root(suite)
        if train_root and not (train_root / "meta" / "info.json").is_file():
            commands.append(
                (
                    "features_only",
                    [
                        *PREDVLA,
                        "features-only",
                        "--dataset-root",
                        str(self.sweep_path(entry["root"])),
                        "--out",
                        str(train_root),
                        "--repo-id",
                        entry["repo_id"],
                    ],
                )
            )
        return commands

    def source_data_commands(self, suite: str) -> list[tuple[str, list[str]]]:
        """(stage, command) still to run to make `suite`'s `root` dataset from its `data` entry: the demonstrations
        its front end is fitted on (every suite of `frontend_from` while the front end is missing, else its own),
        the front-end fit, and the conversion."""
        data = self.sweep.settings.data
        spec = data.get(suite)
        if spec is None:
            return []
        dataset = self.sweep_path(self.sweep.settings.datasets[suite]["root"])
        if (dataset / "meta" / "info.json").is_file():
            return []
        hdf5, frontend = self.sweep_path(spec.hdf5), self.sweep_path(spec.frontend)
        threads = ["--threads", str(spec.frontend_threads)] if spec.frontend_threads != 1 else []
        fitted = fitted_suites(data, suite)
        fit_missing = not (frontend / METADATA_FILE).is_file()
        commands = [c for source in (fitted if fit_missing else [suite]) for c in self.demo_commands(suite, source)]
        if fit_missing:
            roots = list(dict.fromkeys(str(self.sweep_path(data[s].hdf5)) for s in fitted))
            commands.append(
                (
                    "frontend",
                    [
                        *PREDVLA,
                        "fit-frontend",
                        *(arg for root in roots for arg in ("--hdf5-root", root)),
                        "--suites",
                        ",".join(fitted),
                        "--vision-weights",
                        spec.vision_weights,
                        "--language-from",
                        spec.language_from,
                        "--frame-stride",
                        str(spec.frame_stride),
                        *threads,
                        "--out",
                        str(frontend),
                    ],
                )
            )
        commands.append(
            (
                "convert",
                [
                    *PREDVLA,
                    "convert",
                    "--hdf5-root",
                    str(hdf5),
                    "--suite",
                    suite,
                    "--frontend",
                    str(frontend),
                    "--out",
                    str(dataset),
                    "--repo-id",
                    self.sweep.settings.datasets[suite]["repo_id"],
                    "--image-storage",
                    spec.image_storage,
                    *threads,
                    *(["--oracle"] if spec.oracle else []),
                ],
            )
        )
        return commands

    def demo_commands(self, suite: str, source: str) -> list[tuple[str, list[str]]]:
        """(stage, command) of `source`'s missing demonstrations, made in `suite`'s data stage: `demos` (or
        `demos.tasks<k>`, one per `data.workers` share); `demos.<source>...` for another suite whose demonstrations
        `suite`'s front end is fitted on."""
        spec = self.sweep.settings.data[source]
        hdf5 = self.sweep_path(spec.hdf5)
        missing = self.missing_demo_tasks(source, spec, hdf5)
        shares = [missing[k :: spec.workers] for k in range(min(spec.workers, len(missing)))]
        stage = "demos" if source == suite else f"demos.{source}"
        return [
            (
                stage if len(shares) == 1 else f"{stage}.tasks{k}",
                [
                    *PREDVLA,
                    "demos",
                    "--suite",
                    source,
                    "--tasks",
                    ",".join(map(str, share)),
                    "--per-task",
                    str(spec.per_task),
                    "--render-interval",
                    str(spec.render_interval),
                    "--seed",
                    str(spec.demo_seed),
                    "--init-noise",
                    str(spec.init_noise),
                    "--half-turn",
                    spec.half_turn,
                    "--hold-steps",
                    str(spec.hold_steps),
                    *style_args(spec),
                    "--out",
                    str(hdf5),
                ],
            )
            for k, share in enumerate(shares)
        ]

    @staticmethod
    def missing_demo_tasks(suite: str, spec: DataSpec, hdf5: Path) -> list[int]:
        tasks = spec.tasks if spec.tasks is not None else range(num_tasks(suite))
        return [t for t in tasks if not task_file(hdf5, task_spec(suite, t)).is_file()]

    def make_data(self, suite: str) -> bool:
        """Run the missing data stages of `suite` (the `demos[.<suite>].tasks<k>` shares of `data.workers` at once),
        recording each one's command and wall time in `RUNS_DIR/data/<suite>.json`; False when one failed."""
        stages_file = data_stages_path(self.runs_dir, suite)
        kernels = openblas_coretype()  # the stages' processes inherit this process's environment and processor

        def run_stage(stage: str, command: list[str]) -> tuple[str, list[str], int, float]:
            start = time.monotonic()
            code = self.execute(command, self.log_path("data", suite, 0, stage))
            return stage, command, code, time.monotonic() - start

        for name, group in groupby(self.data_commands(suite), key=lambda item: item[0].split(".tasks")[0]):
            group = list(group)
            self.check_stop_at(f"data stage {name} of {suite}")
            with ThreadPoolExecutor(max_workers=len(group)) as pool:
                finished = list(pool.map(lambda item: run_stage(*item), group))
            stages = json.loads(stages_file.read_text()) if stages_file.is_file() else {}
            for stage, command, code, wall in finished:
                if code == 0:  # with the OpenBLAS kernels the stage ran under: demonstrations depend on them
                    stages[stage] = {"command": command, "wall_s": round(wall, 1), "openblas_coretype": kernels}
            atomic_write_json(stages_file, stages)
            failed = [(stage, code) for stage, _, code, _ in finished if code != 0]
            for stage, code in failed:
                print(
                    f"predvla sweep: data stage {stage} of {suite} failed ({describe_exit(code)}); see "
                    f"{self.log_path('data', suite, 0, stage)}",
                    file=sys.stderr,
                )
            if failed:
                return False
        return True
