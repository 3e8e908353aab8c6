"""Writes the options reference (``options.md``): every ``*_DEFAULTS`` dict of the public
functions, each option with its default and the comment written beside it in the source,
so the page cannot drift from the code."""

from __future__ import annotations

import ast
import importlib
import inspect
import io
import tokenize
from pathlib import Path

#: (module, dict, the functions it configures, separated by ", ")
TABLES = [
    ("optkin.solvers.forward", "FORWARD_DEFAULTS", "optkin.forward"),
    ("optkin.solvers.inverse", "INVERSE_DEFAULTS", "optkin.inverse"),
    ("optkin.solvers.enumerate", "ASSEMBLY_DEFAULTS", "optkin.assembly_modes"),
    ("optkin.solvers.enumerate", "TRACK_DEFAULTS", "optkin.track"),
    ("optkin.solvers.batch", "BATCH_DEFAULTS", "optkin.forward_batch"),
    ("optkin.analysis.velocity", "JACOBIANS_DEFAULTS", "optkin.jacobians"),
    ("optkin.analysis.mobility", "DOF_DEFAULTS", "optkin.dof"),
    ("optkin.analysis.singularity", "CLASSIFY_DEFAULTS", "optkin.classify"),
    ("optkin.analysis.continuation", "SINGULAR_CURVES_DEFAULTS", "optkin.singular_curves"),
    ("optkin.analysis.surfaces", "SINGULAR_SURFACES_DEFAULTS", "optkin.singular_surfaces"),
    ("optkin.analysis.cusps", "CUSP_CURVES_DEFAULTS", "optkin.cusp_curves"),
    ("optkin.analysis.cusps", "IS_CUSPIDAL_DEFAULTS", "optkin.is_cuspidal"),
    ("optkin.analysis.cusps", "MODE_CHANGE_DEFAULTS", "optkin.mode_change_path"),
    ("optkin.analysis.aspects", "ASPECTS_DEFAULTS", "optkin.aspects, optkin.workspace"),
    ("optkin.analysis.aspects3d", "ASPECTS3D_DEFAULTS", "optkin.aspects3d"),
    ("optkin.statics.core", "STATICS_DEFAULTS", "the functions of optkin.statics"),
]


def _comments(module: str, name: str) -> dict[str, str]:
    """key -> the comment lines following it in the dict literal (continuation comments
    on their own lines belong to the key before them)."""
    src = inspect.getsource(importlib.import_module(module))
    tree = ast.parse(src)
    node = next(n for n in ast.walk(tree) if isinstance(n, (ast.Assign, ast.AnnAssign))
                and getattr(n.targets[0] if isinstance(n, ast.Assign) else n.target, "id", "")
                == name)
    keys = {k.lineno: k.value for k in node.value.keys if isinstance(k, ast.Constant)}
    out: dict[str, list[str]] = {}
    current = None
    for tok in tokenize.generate_tokens(io.StringIO(src).readline):
        line = tok.start[0]
        if not node.lineno <= line <= node.end_lineno:
            continue
        if line in keys:
            current = keys[line]
        if tok.type == tokenize.COMMENT and current is not None:
            out.setdefault(current, []).append(tok.string.lstrip("#").strip())
    return {k: " ".join(v) for k, v in out.items()}


def options_markdown() -> str:
    out = ["# Options", "",
           "Functions take their options by keyword over a module-level dict of defaults; an",
           "unknown name is reported with the allowed ones. Generated from the source.", ""]
    for module, name, target in TABLES:
        defaults = getattr(importlib.import_module(module), name)
        notes = _comments(module, name)
        names = target.split(", ")
        role = (" and ".join(f"{{func}}`{t}`" for t in names)
                if all(t.startswith("optkin.") and " " not in t for t in names) else target)
        out += [f"## `{name}`", "", f"Options of {role} (`{module}.{name}`).", "",
                "| option | default | meaning |", "|---|---|---|"]
        for key, value in defaults.items():
            note = notes.get(key, "").replace("|", "\\|")
            out.append(f"| `{key}` | `{value!r}` | {note} |")
        out.append("")
    return "\n".join(out)


def write_options_page(path: Path) -> None:
    text = options_markdown()
    if not path.exists() or path.read_text() != text:
        path.write_text(text)
