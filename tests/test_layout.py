"""The code's shape, checked: no import cycle, `forward` never imports `vibinverse`, no model-kind
string switch outside the models, no reach-in to another module's private names, and every module
imports on its own, with nothing else of ours loaded before it."""

import ast
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("forward", "vibinverse")


def _modules() -> dict[str, Path]:
    out = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = path
    return out


MODULES = _modules()


def _imports(name: str, path: Path) -> set[str]:
    """Modules of this project that `name` imports anywhere: at module level, in `if TYPE_CHECKING:`
    blocks (a type-only import is still a dependency) and inside functions (an import deferred to
    run time is one too: a circle of them is a circle of the design)."""
    tree = ast.parse(path.read_text())
    found: set[str] = set()
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package.split(".")[: len(package.split(".")) - node.level + 1] + [base]).strip(".")
            for a in node.names:
                found.add(f"{base}.{a.name}" if f"{base}.{a.name}" in MODULES else base)
    return {m for m in found if m in MODULES and m != name}


GRAPH = {name: _imports(name, path) for name, path in MODULES.items()}


def test_no_import_cycle():
    state: dict[str, int] = {}
    stack: list[str] = []

    def dfs(node):
        state[node] = 1
        stack.append(node)
        for nxt in sorted(GRAPH[node]):
            if state.get(nxt) == 1:
                raise AssertionError("import cycle: " + " -> ".join([*stack[stack.index(nxt) :], nxt]))
            if nxt not in state:
                dfs(nxt)
        stack.pop()
        state[node] = 2

    for name in sorted(GRAPH):
        if name not in state:
            dfs(name)


#: words that name a model, term, component or method kind: comparing a value with one of them is a
#: string switch on a kind (`==`, `!=`, or `in` a literal tuple of them)
KIND_WORDS = frozenset(
    {"mode", "line", "drift", "walk", "integrated", "none", "ar1", "1/f", "flicker", "white", "modal", "frame"}
    | {"oscillator", "spectral", "sindy", "casadi", "map", "importance", "mcmc", "auto", "plate", "rayleigh"}
)
#: a value compared with a kind word is a string switch on a kind: none is left (76 in 13 modules
#: before). Their place is a registry: a class per kind that answers for itself (`vibinverse.terms`,
#: `vibinverse.selection.moves`, `vibinverse.pipeline.FIT_METHODS`, `vibinverse.estimators`).


def kind_switches(path: Path) -> list[int]:
    """Lines of `path` that compare a value with a kind word (`KIND_WORDS`)."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if not isinstance(node, ast.Compare):
            continue
        for op, right in zip(node.ops, node.comparators):
            if isinstance(op, (ast.Eq, ast.NotEq)):
                for side in (node.left, right):
                    if isinstance(side, ast.Constant) and isinstance(side.value, str) and side.value in KIND_WORDS:
                        out.add(node.lineno)
            elif (
                isinstance(op, (ast.In, ast.NotIn))
                and isinstance(right, (ast.Tuple, ast.Set, ast.List))
                and any(isinstance(e, ast.Constant) and e.value in KIND_WORDS for e in right.elts)
            ):
                out.add(node.lineno)
    return sorted(out)


def test_no_kind_switches():
    for name, path in MODULES.items():
        if not name.startswith("vibinverse"):  # forward parses its scene files' spellings
            continue
        found = kind_switches(path)
        assert not found, f"{path}: kind switches at lines {', '.join(map(str, found))}: use a registry"


def test_the_kind_switch_check_can_fail(tmp_path):
    sample = tmp_path / "sample.py"
    sample.write_text('if spec.noise == "ar1":\n    pass\nif method in ("map", "casadi"):\n    pass\nok = "ar1" in d\n')
    assert kind_switches(sample) == [1, 3]


def test_forward_never_imports_vibinverse():
    for name, path in MODULES.items():
        if name.startswith("forward"):
            text = path.read_text()
            assert not re.search(r"^\s*(from|import)\s+vibinverse\b", text, re.M), name


def test_no_model_kind_switch_outside_the_models():
    """Model kinds are chosen by the registry (`vibinverse.models.model_class_for`), not by string
    comparisons spread over the pipeline."""
    kinds = "|".join(["frame", "response", "deterministic", "plate", "rayleigh"])
    pattern = re.compile(rf"""(==|!=)\s*["']({kinds})["']|["']({kinds})["']\s*(==|!=)|\bis_frame\b""")
    for name, path in MODULES.items():
        if name.startswith("vibinverse") and not name.startswith("vibinverse.models"):
            for k, line in enumerate(path.read_text().splitlines(), 1):
                assert not pattern.search(line), f"{path}:{k}: {line.strip()}"


def test_no_reach_in_to_another_modules_private_names():
    for name, path in MODULES.items():
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module:
                private = [a.name for a in node.names if a.name.startswith("_") and not a.name.startswith("__")]
                assert not private, f"{name} imports private {private} from {node.module}"
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name):
                obj, attr = node.value.id, node.attr
                # (the standard library's own documented underscore names, os._exit, are not ours)
                if attr.startswith("_") and not attr.startswith("__") and obj not in ("self", "cls", "os", "sys"):
                    raise AssertionError(f"{path}:{node.lineno}: {obj}.{attr} reaches into a private name")


# Run by one interpreter that has loaded the third-party modules ours use (argv[1], comma-separated;
# any that fail to load alone are left to the module that needs them), then imports each of our
# modules (argv[2:]) in a child forked from that state, two at a time: nothing of ours is loaded
# before the module under test, and each child skips the ~1 s of numpy, scipy, numba and casadi
# imports (a fresh interpreter per module took 115 s on a slow machine).
_FORK_IMPORTS = r"""
import importlib, os, sys, traceback
for name in sys.argv[1].split(","):
    try:
        importlib.import_module(name)
    except Exception:
        pass
bad, running = [], {}
def reap():
    pid, status = os.wait()
    name, r = running.pop(pid)
    err = os.read(r, 1 << 15).decode(errors="replace").strip()
    os.close(r)
    if status:
        bad.append(name + ": " + (err.splitlines()[-1] if err else f"exit status {status}"))
for name in sys.argv[2:]:
    if len(running) >= 2:
        reap()
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:
        os.close(r)
        try:
            importlib.import_module(name)
            code = 0
        except BaseException:
            os.write(w, traceback.format_exc()[-8000:].encode())
            code = 1
        os._exit(code)
    os.close(w)
    running[pid] = (name, r)
while running:
    reap()
print("\n".join(bad))
"""

_THIRD_PARTY = r"""
import importlib, sys
for name in sys.argv[1:]:
    try:
        importlib.import_module(name)
    except Exception:
        pass  # reported by the check itself
ours = {"forward", "vibinverse", "tests", "__main__"}
print(",".join(sorted(m for m in list(sys.modules) if m.split(".")[0] not in ours)))
"""


@pytest.mark.slow
@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs os.fork")
def test_every_module_imports_alone():
    """Each module of ours in its own process with none of ours loaded before it, so that a module
    that imports only because another one was imported before it fails here. (`__main__` modules
    run the CLI.) Third-party modules are loaded first, once: they are not what this checks."""
    mods = [m for m in MODULES if not m.endswith("__main__")]
    run = {"capture_output": True, "text": True, "cwd": ROOT, "check": True}
    third = subprocess.run([sys.executable, "-c", _THIRD_PARTY, *mods], **run).stdout.strip()
    assert "numpy" in third.split(",")  # the probe saw what ours import
    out = subprocess.run([sys.executable, "-c", _FORK_IMPORTS, third, *mods], **run).stdout.strip()
    assert not out, out
