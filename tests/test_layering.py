"""The package's shape, read from its imports with `ast`: no import cycle, no import against the layering, and the
research diagnostics beside the package, never inside it.

Parts are the top-level modules and folders of `lerobot_predvla`; a policy folder under `policies/` and a simulator
folder under `sims/` are parts of their own. `ALLOWED` lists, bottom up, the parts each part may import; `EXCEPTIONS`
the imports that still run against it, each with its reason (the test fails once one is no longer needed, so the
list only shrinks). `research/` (the diagnostics behind docs/research/, not installed) may import the package; the
package never imports it, and whatever the package defines for research it uses itself. No module of either is
longer than MAX_LINES.
"""

import ast
import re
from collections import defaultdict
from pathlib import Path

PACKAGE = "lerobot_predvla"
RESEARCH = "research"
ROOT = Path(__file__).resolve().parents[1] / PACKAGE
RESEARCH_ROOT = ROOT.parent / RESEARCH
MAX_LINES = 600
OWN_PARTS = ("policies", "sims")  # folders whose subfolders are parts of their own

_BASE = {"utils", "columns"}
_POLICIES = {"policies", "policies.common", "policies.predvla", "policies.bc_rnn", "policies.bc_transformer",
             "policies.ladder"}
_BELOW_SIMULATORS = _BASE | {"frontend", "data", "robots", "lerobot_commands"} | _POLICIES
_SIMULATORS = {"sims", "sims.libero"}
ALLOWED = {
    "utils": set(),
    "columns": set(),  # column names and shared constants
    "lerobot_commands": set(),  # the command lines of lerobot-train and lerobot-eval
    "frontend": _BASE,
    "data": _BASE | {"frontend"},  # every reader, and what runs the front end over a dataset
    "robots": _BASE,
    "policies": _BASE,  # POLICY_TYPES and the recipe fields of a policy config
    "policies.common": _BASE | {"frontend", "policies"},  # the shared layer of every policy
    "policies.predvla": _BASE | {"frontend", "policies", "policies.common"},
    "policies.bc_rnn": _BASE | {"frontend", "policies", "policies.common"},
    "policies.bc_transformer": _BASE | {"frontend", "policies", "policies.common"},
    "policies.ladder": _BASE | {"frontend", "policies", "policies.common", "policies.predvla"},  # PredVLA, cut down
    "sims": set(),  # one folder per simulator, nothing of its own
    "sims.libero": _BELOW_SIMULATORS,  # the simulator and its LeRobot env type
    "hub": _BELOW_SIMULATORS | _SIMULATORS,
    "lerobot_integration": _BELOW_SIMULATORS | _SIMULATORS,
    "sweep": _BELOW_SIMULATORS | _SIMULATORS,  # the sweep runner: data, lerobot-train, lerobot-eval, run records
    "report": _BELOW_SIMULATORS | _SIMULATORS | {"hub", "sweep"},  # reports of sweeps, the headline, model cards
    "cli": _BELOW_SIMULATORS | _SIMULATORS | {"hub", "sweep", "report"},
}
# (importing module, imported part): why the import runs against ALLOWED for now.
EXCEPTIONS: dict[tuple[str, str], str] = {}
# Function-level imports of the package's own modules: each waits for an optional heavy dependency (the simulator:
# LIBERO, robosuite, MuJoCo) and says so.
MAX_FUNCTION_LEVEL_IMPORTS = 5


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def part_of(module: str) -> str:
    """`lerobot_predvla.policies.predvla.x` -> `policies.predvla`; `lerobot_predvla.sims.libero.x` ->
    `sims.libero`; `lerobot_predvla.hub.card` -> `hub`; the package's own `__init__` (the registration, which
    imports every part) -> ``."""
    names = module.split(".")[1:]
    if len(names) > 1 and names[0] in OWN_PARTS and (ROOT / names[0] / names[1]).is_dir():
        return f"{names[0]}.{names[1]}"
    return names[0] if names else ""


def own_imports(path: Path, module: str) -> list[tuple[str, bool, int]]:
    """(imported module of the package, inside a function, line) for every import of `path`."""
    tree = ast.parse(path.read_text())
    in_function = {id(node) for f in ast.walk(tree) if isinstance(f, ast.FunctionDef | ast.AsyncFunctionDef)
                   for node in ast.walk(f)}
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*anchor, *([base] if base else [])])
            targets = [f"{base}.{alias.name}" for alias in node.names]
            targets = [t if MODULES.get(t) else base for t in targets]
        else:
            continue
        for target in targets:
            if target == PACKAGE or target.startswith(PACKAGE + "."):
                found.append((target, id(node) in in_function, node.lineno))
    return found


MODULES = {module_name(p): p for p in sorted(ROOT.rglob("*.py"))}
IMPORTS = {module: own_imports(path, module) for module, path in MODULES.items()}


def graph() -> dict[str, set[str]]:
    edges = defaultdict(set)
    for module, imports in IMPORTS.items():
        edges[module] |= {target for target, _, _ in imports if target != module}
    return edges


def test_no_import_cycle():
    edges, state, cycles = graph(), {}, []

    def visit(module: str, stack: list[str]) -> None:
        state[module] = "open"
        for target in sorted(edges[module]):
            if state.get(target) == "open":
                cycles.append(stack[stack.index(target):] + [target])
            elif target not in state:
                visit(target, [*stack, target])
        state[module] = "done"

    for module in sorted(MODULES):
        if module not in state:
            visit(module, [module])
    assert not cycles, "import cycles: " + "; ".join(" -> ".join(c) for c in cycles)


def test_nothing_imports_the_package_root():
    """Only LeRobot's plugin loader and users import `lerobot_predvla` itself (the registration)."""
    assert not [m for m, imports in IMPORTS.items() for target, _, _ in imports if target == PACKAGE]


def test_every_import_follows_the_layering():
    unused = set(EXCEPTIONS)
    against = []
    for module, imports in IMPORTS.items():
        part = part_of(module)
        assert part == "" or part in ALLOWED, f"{module}: part {part!r} is missing from ALLOWED"
        for target, _, _ in imports:
            target_part = part_of(target)
            if part == "" or target_part in ("", part) or target_part in ALLOWED[part]:
                continue
            key = (module.removeprefix(PACKAGE + "."), target_part)
            if key in EXCEPTIONS:
                unused.discard(key)
            else:
                against.append(f"{module} -> {target}")
    assert not against, "imports against the layering:\n" + "\n".join(sorted(set(against)))
    assert not unused, f"exceptions no longer needed (remove them): {sorted(unused)}"


def test_function_level_imports_of_the_package_are_few_and_say_why():
    """At most MAX_FUNCTION_LEVEL_IMPORTS import statements of the package's own modules wait for their function's
    call, each with a comment (on its line or the line above) saying why."""
    found = sorted({(module, line) for module, imports in IMPORTS.items() for _, inside, line in imports if inside})
    assert len(found) <= MAX_FUNCTION_LEVEL_IMPORTS, "\n".join(f"{m}:{line}" for m, line in found)
    for module, line in found:
        lines = MODULES[module].read_text().splitlines()
        statement, above = lines[line - 1], lines[line - 2].strip()
        assert "#" in statement or above.startswith("#"), f"{module}:{line}: say why this import waits for its call"


def absolute_imports(path: Path) -> list[tuple[str, list[str]]]:
    """(imported module, imported names) of every absolute import statement of `path`."""
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found += [(alias.name, []) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
            found.append((node.module, [alias.name for alias in node.names]))
    return found


def test_the_package_never_imports_research():
    """`research/` is not installed: an import of it from the package would fail on every user's machine."""
    against = [f"{path.relative_to(ROOT.parent)}: {module}" for path in ROOT.rglob("*.py")
               for module, names in absolute_imports(path)
               if module == RESEARCH or module.startswith(RESEARCH + ".")]
    assert not against, "the package imports research/:\n" + "\n".join(against)


def test_what_research_imports_from_the_package_the_package_uses_itself():
    """Every name `research/` imports from the package is also used by the package (outside the line that defines
    it): nothing in the installed package is there only for research."""
    texts = {path: path.read_text() for path in ROOT.rglob("*.py")}
    unused = []
    for path in sorted(RESEARCH_ROOT.rglob("*.py")):
        for module, names in absolute_imports(path):
            if not module.startswith(PACKAGE + "."):
                continue
            for name in names:
                word = re.compile(rf"\b{re.escape(name)}\b")
                uses = sum(len(word.findall(text)) for text in texts.values())
                definitions = sum(len(re.findall(rf"^\s*(?:def |class ){re.escape(name)}\b|^{re.escape(name)}\s*[:=]",
                                                 text, flags=re.M)) for text in texts.values())
                if uses - definitions < 1:
                    unused.append(f"{path.relative_to(ROOT.parent)}: {module}.{name}")
    assert not unused, "used by research/ only (move them to research/):\n" + "\n".join(unused)


def test_research_is_a_tree_beside_the_package():
    assert (RESEARCH_ROOT / "__init__.py").is_file() and not (ROOT / "experiments").exists()


def test_no_module_is_longer_than_max_lines():
    long = {str(p.relative_to(ROOT.parent)): n for base in (ROOT, RESEARCH_ROOT) for p in sorted(base.rglob("*.py"))
            if (n := len(p.read_text().splitlines())) > MAX_LINES}
    assert not long, f"modules over {MAX_LINES} lines (split them by job): {long}"
