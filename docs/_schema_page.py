"""Writes the problem-file reference page from the JSON Schema of the problem files (run by
``conf.py`` at every build, so the page cannot drift from the validator)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any


def _type(spec: dict[str, Any], defs: dict[str, Any]) -> str:
    if "$ref" in spec:
        return f"[{spec['$ref'].rsplit('/', 1)[-1]}](#{_anchor(spec['$ref'].rsplit('/', 1)[-1])})"
    if "enum" in spec:
        return " \\| ".join(f"`{json.dumps(v)}`" for v in spec["enum"])
    if "const" in spec:
        return f"`{json.dumps(spec['const'])}`"
    for key in ("anyOf", "oneOf"):
        if key in spec:
            return " or ".join(_type(s, defs) for s in spec[key])
    t = spec.get("type", "any")
    if t == "array" and "items" in spec:
        return f"array of {_type(spec['items'], defs)}"
    if t == "object" and isinstance(spec.get("additionalProperties"), dict):
        return f"table of {_type(spec['additionalProperties'], defs)}"
    return str(t) if not isinstance(t, list) else " or ".join(t)


def _anchor(name: str) -> str:
    return name.lower().replace("_", "-")


def _cell(text: str) -> str:
    return " ".join(str(text).split()).replace("|", "\\|")


def _table(spec: dict[str, Any], defs: dict[str, Any]) -> list[str]:
    props = spec.get("properties", {})
    if not props:
        return []
    required = set(spec.get("required", ()))
    rows = ["| key | type | required | default | description |", "|---|---|---|---|---|"]
    for key, p in props.items():
        default = f"`{json.dumps(p['default'])}`" if "default" in p else ""
        rows.append(f"| `{key}` | {_type(p, defs)} | {'yes' if key in required else ''} "
                    f"| {_cell(default)} | {_cell(p.get('description', ''))} |")
    return rows


def schema_markdown() -> str:
    from optkin.problems.schema import problem_json_schema

    schema = problem_json_schema()
    defs = schema.get("$defs", {})
    out = [
        "# Problem-file reference",
        "",
        "Generated from the JSON Schema that `optkin schema` prints (the same schema the",
        "runner validates against), so it cannot drift from the code. Point an editor at",
        "the schema to have problem files checked as you type:",
        "",
        "```bash",
        "optkin schema --out optkin-problem.schema.json",
        "```",
        "",
        "For example with Taplo (VS Code's *Even Better TOML*), add",
        "`#:schema ./optkin-problem.schema.json` as the first line of a problem file.",
        "",
        "## The file",
        "",
        _cell(schema.get("description", "")),
        "",
        *_table(schema, defs),
        "",
    ]
    for name, spec in defs.items():
        out += [f"## {name}", ""]
        if spec.get("description"):
            out += [_cell(spec["description"]), ""]
        rows = _table(spec, defs)
        out += rows if rows else [f"Type: {_type(spec, defs)}"]
        out.append("")
    return "\n".join(out)


def write_schema_page(path: Path) -> None:
    text = schema_markdown()
    if not path.exists() or path.read_text() != text:  # unchanged: no rebuild of the page
        path.write_text(text)
