"""The package tree: the 0.1 names are gone in 0.2.0 and CHANGELOG.md says where they went
(issue 48 item 6; issue 27 item 1 moved them), every module imports without a warning, no
module imports another that imports it back, and the packages import only lower layers
(issue 48 item 5)."""

from __future__ import annotations

import ast
import importlib
import subprocess
import sys
from pathlib import Path

import pytest

import sdr_di

PKG = Path(sdr_di.__file__).parent

#: old module -> new module
MOVED_MODULES = {
    "sdr_di.deep.vector_loop": "sdr_di.integration.receiver",
    "sdr_di.deep.run_deep": "sdr_di.integration.run_integrated",
    "sdr_di.experiments.study_spec": "sdr_di.studies.spec",
    "sdr_di.experiments.report": "sdr_di.studies.campaign_report",
    **{f"sdr_di.experiments.{m}": f"sdr_di.studies.{m}" for m in (
        "aggregate", "campaign", "commands", "execute", "outputs", "paired", "single_run",
        "study", "study_report", "tables", "tasks")},
    # 0.2.0 (issue 48)
    "sdr_di.integration.config": "sdr_di.coupling.config",
    "sdr_di.integration.measurements": "sdr_di.coupling.measurements",
}

#: (old module, old name) -> (new module, new name)
MOVED_NAMES = {
    ("sdr_di.deep", "DeepReceiver"): ("sdr_di.integration.receiver", "IntegratedReceiver"),
    ("sdr_di.deep", "DeepConfig"): ("sdr_di.coupling.config", "IntegrationConfig"),
    ("sdr_di.deep", "IntegrationConfig"): ("sdr_di.coupling.config", "IntegrationConfig"),
    ("sdr_di.deep", "DeepResult"): ("sdr_di.integration.receiver", "IntegrationResult"),
    ("sdr_di.deep", "HandoverError"): ("sdr_di.errors", "HandoverError"),
    ("sdr_di.deep", "MODES"): ("sdr_di.coupling.config", "MODES"),
    ("sdr_di.integration.receiver", "DeepConfig"): ("sdr_di.coupling.config",
                                                    "IntegrationConfig"),
    ("sdr_di.integration.receiver", "DeepReceiver"): ("sdr_di.integration.receiver",
                                                      "IntegratedReceiver"),
    ("sdr_di.integration.receiver", "clock_model"): ("sdr_di.integration.filter_setup",
                                                     "clock_model"),
    ("sdr_di.integration.receiver", "gnss_alignment"): ("sdr_di.integration.alignment",
                                                        "gnss_alignment"),
    ("sdr_di.experiments", "run_campaign"): ("sdr_di.studies.campaign", "run_campaign"),
    ("sdr_di.experiments", "render_report"): ("sdr_di.studies.campaign_report",
                                              "render_report"),
    ("sdr_di.experiments", "run_experiment"): ("sdr_di.studies.single_run",
                                               "run_experiment"),
    # 0.2.0 (issue 48)
    ("sdr_di.integration.run_integrated", "run_deep"): ("sdr_di.integration.run_integrated",
                                                        "run_integrated"),
    ("sdr_di.integration.run_integrated", "DeepRunSummary"): (
        "sdr_di.integration.run_integrated", "IntegratedRunSummary"),
    ("sdr_di.integration.run_integrated", "DEEP_COLUMNS"): (
        "sdr_di.integration.run_integrated", "SOLUTION_COLUMNS"),
    ("sdr_di.integration.run_integrated", "write_deep_csv"): (
        "sdr_di.integration.run_integrated", "write_solution_csv"),
    ("sdr_di.integration.loose", "make_inputs"): ("sdr_di.sim.lc_inputs", "make_inputs"),
    ("sdr_di.integration.loose", "run_loose_scenario"): ("sdr_di.sim.lc_inputs",
                                                         "run_loose_scenario"),
    ("sdr_di.experiments.filter_figures", "parse_filter_spec"): (
        "sdr_di.experiments.entries", "check_filter_entry"),
    ("sdr_di.experiments.filter_figures", "canonical_entry"): ("sdr_di.filters.spec",
                                                               "canonical_entry"),
    ("sdr_di.experiments.filter_figures", "filter_list"): ("sdr_di.experiments.entries",
                                                           "filter_list"),
    ("sdr_di.experiments.filter_figures", "rmse_bar_plot"): ("sdr_di.experiments.plotting",
                                                             "rmse_bar_plot"),
    ("sdr_di.deep.vector_tracking", "_Chan"): ("sdr_di.deep.vector_tracking",
                                               "VectorChannel"),
    ("sdr_di.orbits.rinex_nav", "_toc_datetime"): ("sdr_di.orbits.rinex_nav", "toc_datetime"),
}


CHANGELOG = (PKG.parent / "CHANGELOG.md").read_text()


@pytest.mark.parametrize("old, new", sorted(MOVED_MODULES.items()))
def test_old_module_names_are_gone_and_the_changelog_names_their_new_place(old, new):
    sys.modules.pop(old, None)
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module(old)
    assert f"`{old}`" in CHANGELOG and f"`{new}`" in CHANGELOG
    importlib.import_module(new)


@pytest.mark.parametrize("old, new", sorted(MOVED_NAMES.items()))
def test_old_names_are_gone_and_the_changelog_names_their_new_place(old, new):
    with pytest.raises(AttributeError):
        getattr(importlib.import_module(old[0]), old[1])
    assert f"`{old[0]}.{old[1]}`" in CHANGELOG and f"`{new[0]}.{new[1]}`" in CHANGELOG
    assert getattr(importlib.import_module(new[0]), new[1])


def test_new_names_import_without_deprecation_warnings():
    """Every module of the package, the CLI and the scripts' imports: no DeprecationWarning
    from sdr-di's own old names (a fresh interpreter, warnings as errors)."""
    mods = sorted(".".join(p.relative_to(PKG.parent).with_suffix("").parts)
                  for p in PKG.rglob("*.py") if p.name != "__init__.py")
    code = ("import importlib, warnings\n"
            "warnings.filterwarnings('error', message='.*is deprecated and will be removed',"
            " category=DeprecationWarning)\n"
            f"for m in {mods!r}:\n    importlib.import_module(m)\n")
    subprocess.run([sys.executable, "-c", code], check=True, capture_output=True)


def _import_graph() -> dict[str, set[str]]:
    """sdr_di's module graph: module-level imports (TYPE_CHECKING blocks included)."""
    mods = {}
    for p in PKG.rglob("*.py"):
        rel = p.relative_to(PKG.parent).with_suffix("")
        mods[".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts)] = p
    graph = {}
    for name, p in mods.items():
        pkg = name if p.name == "__init__.py" else name.rpartition(".")[0]
        body = list(ast.parse(p.read_text()).body)
        for n in list(body):
            if isinstance(n, ast.If):
                body += n.body
        deps = set()
        for n in body:
            if isinstance(n, ast.ImportFrom):
                base = pkg
                for _ in range(n.level - 1):
                    base = base.rpartition(".")[0]
                m = (f"{base}.{n.module}" if n.module else base) if n.level else n.module
                for a in n.names:
                    deps.add(f"{m}.{a.name}" if f"{m}.{a.name}" in mods else m)
            elif isinstance(n, ast.Import):
                deps.update(a.name for a in n.names)
        graph[name] = {d for d in deps if d in mods and d != name}
    return graph


def test_no_module_import_cycles():
    """No module-level import circle (deep/vector_loop <-> deep/vector_tracking was one)."""
    graph = _import_graph()
    state: dict[str, int] = {}
    cycles = []

    def visit(v, path):
        state[v] = 1
        for w in graph[v]:
            if state.get(w) == 1:
                cycles.append(path[path.index(w):] + [w])
            elif w not in state:
                visit(w, path + [w])
        state[v] = 2

    for v in sorted(graph):
        if v not in state:
            visit(v, [v])
    assert not cycles, cycles


def test_studies_import_experiments_never_the_reverse():
    graph = _import_graph()
    up = {(a, b) for a, deps in graph.items() for b in deps
          if a.startswith("sdr_di.experiments") and b.startswith("sdr_di.studies")}
    assert not up, up


# ---- layers (issue 48 item 5) -----------------------------------------------------------------
#: The packages (and top-level modules) of sdr_di in layers, lowest first. A package imports
#: only packages of lower layers, at module level or inside a function: the layer of the
#: data flow (DESIGN section 2) it belongs to. ``coupling`` holds what deep mode's
#: measurement source and the integration loop share, below both.
LAYERS: tuple[tuple[str, ...], ...] = (
    ("errors",),
    ("constants", "settings", "kernel_cache", "paths"),
    ("timebase", "frames", "oscillator", "filters"),
    ("orbits", "ins"),
    ("scenario", "signal", "io", "coupling"),
    ("receiver",),
    ("deep",),
    ("integration",),
    ("sim",),
    ("experiments",),
    ("studies",),
    ("report",),
    ("options",),
    ("api",),
    ("cli",),
)
#: Private modules other packages still import, each with its reason.
PRIVATE_MODULES_USED_AS_PUBLIC = {
    "sdr_di.experiments._deep",    # the studies' file cache and truth check (rename pending)
}


def _package_imports() -> list[tuple[str, str, str, list[str], Path]]:
    """Every import of one sdr_di package by another: (importer package, imported package,
    imported module, imported names, file); function-level imports included."""
    out = []
    for p in PKG.rglob("*.py"):
        rel = p.relative_to(PKG.parent).with_suffix("").parts
        mod = rel[:-1] if rel[-1] == "__init__" else rel
        src = rel[1] if len(rel) > 1 else "__init__"
        for n in ast.walk(ast.parse(p.read_text())):
            if isinstance(n, ast.ImportFrom):
                if n.level:
                    base = list(mod if p.name == "__init__.py" else mod[:-1])
                    base = base[:len(base) - n.level + 1]
                    target = base + (n.module.split(".") if n.module else [])
                elif (n.module or "").split(".")[0] == "sdr_di":
                    target = n.module.split(".")
                else:
                    continue
                names = [a.name for a in n.names]
            elif isinstance(n, ast.Import):
                hits = [a.name.split(".") for a in n.names if a.name.split(".")[0] == "sdr_di"]
                if not hits:
                    continue
                target, names = hits[0], []
            else:
                continue
            dst = target[1] if len(target) > 1 else "__init__"
            if dst != src:
                out.append((src, dst, ".".join(target), names, p))
    return out


def test_packages_import_only_lower_layers():
    """The layer table above: no package imports one of its own or a higher layer (receiver
    never imports integration or sim; deep never imports integration). ``from .. import
    __version__`` (the package's version) is allowed anywhere."""
    rank = {name: i for i, layer in enumerate(LAYERS) for name in layer}
    packages = {p.stem if p.is_file() else p.name for p in PKG.iterdir()
                if (p.suffix == ".py" or (p / "__init__.py").is_file())
                and p.name != "__init__.py"}
    assert packages <= set(rank), f"not in LAYERS: {sorted(packages - set(rank))}"
    bad = sorted({(src, dst, str(f.relative_to(PKG.parent)))
                  for src, dst, _, names, f in _package_imports()
                  if not (dst == "__init__" and names == ["__version__"])
                  and src != "__init__"
                  and not rank[dst] < rank[src]})
    assert not bad, bad


def test_no_package_imports_another_packages_private_names():
    bad = sorted((str(f.relative_to(PKG.parent)), m, n)
                 for src, dst, m, names, f in _package_imports()
                 for n in [*names, m.split(".")[-1]]
                 if n.startswith("_") and not n.startswith("__")
                 and m not in PRIVATE_MODULES_USED_AS_PUBLIC)
    assert not bad, bad


def test_deep_never_imports_integration():
    """Deep mode's measurement source reads the settings, the interval and the measurement
    model from sdr_di.coupling (the integration loop runs it; it does not know the loop)."""
    assert not [f for src, dst, _, _, f in _package_imports()
                if src == "deep" and dst == "integration"]


# ---- environment switches (issue 48 item 6) ---------------------------------------------------
def test_environment_switches_are_read_in_settings_only():
    """SDR_DI_* variables are named in sdr_di/settings.py and nowhere else in the package."""
    named = sorted(str(p.relative_to(PKG.parent)) for p in PKG.rglob("*.py")
                   if p.name != "settings.py"
                   and any(isinstance(n, ast.Constant) and isinstance(n.value, str)
                           and n.value.startswith("SDR_DI_")
                           for n in ast.walk(ast.parse(p.read_text()))))
    assert not named, named


def test_importing_sdr_di_sets_nothing_in_the_environment():
    """Every module imported in a fresh interpreter: os.environ as before (the generator
    asked for OMP_WAIT_POLICY=PASSIVE at import; now when it starts,
    sdr_di.settings.passive_kernel_workers)."""
    mods = sorted(".".join(p.relative_to(PKG.parent).with_suffix("").parts)
                  for p in PKG.rglob("*.py") if p.name not in ("__init__.py", "__main__.py"))
    code = ("import importlib, os\n"
            "os.environ.pop('OMP_WAIT_POLICY', None)\n"
            "before = dict(os.environ)\n"
            f"for m in {mods!r}:\n    importlib.import_module(m)\n"
            "print(sorted(set(os.environ.items()) ^ set(before.items())))\n")
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True,
                         text=True).stdout
    assert out.strip() == "[]"
