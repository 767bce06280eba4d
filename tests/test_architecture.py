"""The shape of the system (docs/architecture.md): one-way layers, no private names across modules.

Walks the import graph of ``ffls/``, ``viewer/``, ``tests/`` and ``benchmarks/`` with :mod:`ast`
(nothing is imported) and fails on

* an import from a higher stage into a lower one (the ranks below);
* ``ffls`` importing ``viewer`` (the viewer registers its own command through an entry point);
* a private name (``_x``, not ``__x__``) of one module used in another: ``from m import _x``,
  ``m._x`` on an imported module, or ``obj._x`` on anything but ``self``/``cls``.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: Stage ranks: a module may import its own package and packages of a strictly lower rank.
RANKS = {
    "ffls.conventions": 0, "ffls.errors": 0,
    "ffls.io": 1,
    "ffls.radiance": 2, "ffls.camera": 2, "ffls.lightmaps": 2,
    "ffls.display": 3, "ffls.spheres": 3, "ffls.weights": 3, "ffls.store": 3,
    "ffls.probes": 4, "ffls.relight": 4,
    "ffls.gpu": 5, "ffls.synth": 5, "ffls.cluster": 5,
    "ffls.demo": 6,
    "ffls.commands": 7, "ffls.cli": 8, "ffls.__main__": 9,
    "ffls.shaders": 0, "ffls.assets": 0,
}
#: Packages that the rank rule does not cover, with what they may import.
LOWEST_STAGES = ("ffls.io", "ffls.radiance", "ffls.camera", "ffls.lightmaps")
HIGH_STAGES = ("ffls.store", "ffls.cluster", "ffls.spheres", "ffls.probes", "ffls.weights", "ffls.relight", "ffls.gpu", "ffls.synth", "ffls.commands")


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _stage(mod: str) -> str | None:
    for name in sorted(RANKS, key=len, reverse=True):
        if mod == name or mod.startswith(name + "."):
            return name
    return "ffls" if mod == "ffls" else None


def _sources(*folders: str) -> list[Path]:
    return sorted(p for f in folders for p in (ROOT / f).rglob("*.py"))


def _imports(path: Path):
    """(line, imported module, imported names) of every import in ``path``, relative ones resolved."""
    tree = ast.parse(path.read_text(), str(path))
    mod = _module_name(path)
    pkg = mod.split(".") if path.name == "__init__.py" else mod.split(".")[:-1]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                yield node.lineno, a.name, ()
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = pkg[: len(pkg) - (node.level - 1)]
                base = ".".join(up + ([base] if base else []))
            yield node.lineno, base, tuple(a.name for a in node.names)


def _layer_violations() -> list[str]:
    bad = []
    for path in _sources("ffls"):
        me = _module_name(path)
        my_stage = _stage(me)
        for line, target, names in _imports(path):
            where = f"{path.relative_to(ROOT)}:{line}"
            if target == "viewer" or target.startswith("viewer."):
                bad.append(f"{where}: ffls imports {target}")
                continue
            if not target.startswith("ffls"):
                continue
            targets = [target] + [f"{target}.{n}" for n in names if target == "ffls"]
            for t in targets if target == "ffls" and names else [target]:
                st = _stage(t)
                if st is None or st == "ffls" or st == my_stage or my_stage in ("ffls", None):
                    continue
                if RANKS[st] >= RANKS[my_stage]:
                    bad.append(f"{where}: {me} (rank {RANKS[my_stage]}) imports {t} (rank {RANKS[st]})")
    return bad


#: Standard-library names that are public although they start with '_' (documented as such):
#: ``os._exit`` ends a process at once, without the interpreter's exit (ffls.__main__).
_PUBLIC_UNDERSCORED = {("os", "_exit")}


def _private_violations(folders) -> list[str]:
    bad = []
    for path in _sources(*folders):
        tree = ast.parse(path.read_text(), str(path))
        me = _module_name(path)
        for line, target, names in _imports(path):
            if target != me and any(n.startswith("_") and not n.startswith("__") for n in names):
                bad.append(f"{path.relative_to(ROOT)}:{line}: imports private {names} from {target}")
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__")
                    and not (isinstance(node.value, ast.Name) and node.value.id in ("self", "cls"))
                    and not (isinstance(node.value, ast.Name) and (node.value.id, node.attr) in _PUBLIC_UNDERSCORED)):
                bad.append(f"{path.relative_to(ROOT)}:{node.lineno}: uses private attribute .{node.attr}")
    return bad


def test_layers_are_one_way():
    assert _layer_violations() == []


def test_lowest_stages_import_no_higher_stage():
    bad = []
    for path in _sources(*[s.replace(".", "/") for s in LOWEST_STAGES]):
        for line, target, _ in _imports(path):
            if any(target == h or target.startswith(h + ".") for h in HIGH_STAGES):
                bad.append(f"{path.relative_to(ROOT)}:{line}: imports {target}")
    assert bad == []


@pytest.mark.parametrize("folders", [("ffls", "viewer"), ("tests",), ("benchmarks",)], ids=["library", "tests", "benchmarks"])
def test_no_private_names_across_modules(folders):
    assert _private_violations(folders) == []


def test_every_module_has_a_stage():
    unknown = [_module_name(p) for p in _sources("ffls") if _stage(_module_name(p)) is None]
    assert unknown == []


def test_the_checker_sees_violations(tmp_path, monkeypatch):
    """The walker itself: a planted upward import and a planted private use are found."""
    pkg = tmp_path / "ffls" / "io"
    pkg.mkdir(parents=True)
    (tmp_path / "ffls" / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("")
    (pkg / "x.py").write_text("from ffls.gpu.engine import Engine\nfrom ffls.io.y import _hidden\nimport viewer\na = b._c\n")
    monkeypatch.setattr(__import__(__name__), "ROOT", tmp_path)
    layers = _layer_violations()
    assert any("ffls.gpu.engine" in v for v in layers) and any("imports viewer" in v for v in layers)
    priv = _private_violations(("ffls",))
    assert any("_hidden" in v for v in priv) and any("._c" in v for v in priv)
