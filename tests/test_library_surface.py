"""What ``import ermrl`` does to a user's process (nothing to JAX or matplotlib), its public names, and the
one-way imports among its modules."""

import ast
import os
import subprocess
import sys
from pathlib import Path

import ermrl

ROOT = Path(__file__).resolve().parents[1] / "ermrl"


def _probe(imports: str) -> str:
    """jax.device_count() and matplotlib's backend after ``imports``, in a fresh process asked for the SVG backend
    (so that a module forcing Agg would show)."""
    code = f"{imports}import jax, matplotlib; print(jax.device_count(), matplotlib.get_backend())"
    env = {**os.environ, "MPLBACKEND": "svg"}
    env.pop("ERMRL_CPU_DEVICES", None)
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True,
                          timeout=300).stdout


def test_importing_ermrl_changes_neither_jax_nor_matplotlib():
    plain = _probe("")
    assert plain == _probe("import ermrl.wrappers; ")
    assert plain == _probe("import ermrl, ermrl.analysis.report, ermrl.analysis.hp_map, ermrl.analysis.context; ")


def test_the_public_names_resolve():
    for name in ermrl.__all__:
        assert getattr(ermrl, name) is not None, name
    assert ermrl.DEFAULT_PHI == ermrl.Phi(0.95, 0.5, 1.0)


def _imports(path: Path, modules: set[str]) -> set[str]:
    """The ermrl modules ``path`` imports anywhere (also inside functions). ``from PKG import SUB`` counts as an
    import of PKG.SUB only, when SUB is a module."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] == "ermrl":
            subs = {f"{node.module}.{a.name}" for a in node.names} & modules
            found |= subs | ({node.module} if len(subs) < len(node.names) else set())
        elif isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name.split(".")[0] == "ermrl"}
    return found & modules


def test_no_import_cycles_among_ermrls_modules():
    paths = {}
    for p in ROOT.rglob("*.py"):
        parts = p.relative_to(ROOT.parent).with_suffix("").parts
        paths[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = p
    graph = {m: _imports(p, set(paths)) - {m} for m, p in paths.items()}
    cycles, state = [], {}

    def visit(m, stack):
        state[m] = "open"
        for n in sorted(graph[m]):
            if state.get(n) == "open":
                cycles.append(stack[stack.index(n):] + [n])
            elif n not in state:
                visit(n, stack + [n])
        state[m] = "done"

    for m in sorted(graph):
        if m not in state:
            visit(m, [m])
    assert cycles == []
