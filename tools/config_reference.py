"""Write config/README.md: every key of config/config.schema.yaml with its type, allowed values,
schema default, the embedded default's value (config/config.yaml) and its description; and
config/config.schema.json, the schema's JSON copy the settings objects read fast.

    .venv/bin/python tools/config_reference.py            # rewrite config/README.md
    .venv/bin/python tools/config_reference.py --check    # exit 1 if it is out of date

The schema is the one source: tests/test_docs.py fails when config/README.md differs from
what this writes, so the page cannot drift from the keys the workflow validates.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tacgen_lib.io.config import load_yaml, schema_copy  # noqa: E402

HEADER = """# Configuration keys

Written from `config/config.schema.yaml` by `tools/config_reference.py` (do not edit by hand:
`make test` fails when this page and the schema differ). A run validates its merged config
against the schema before any job starts and stops naming the key of a bad value. *default* is
the schema's (filled in where a config leaves the key out); *config.yaml* is the embedded
default's own value where it sets one. `config/test.yaml`, `config/paper.yaml` and
`config/cost.yaml` are merged over `config/config.yaml`.
"""


def _resolve(node: Mapping[str, Any], root: Mapping[str, Any]) -> Mapping[str, Any]:
    if "$ref" in node:
        return root["$defs"][node["$ref"].split("/")[-1]]
    return node


def _type(node: Mapping[str, Any]) -> str:
    if "enum" in node:
        return " \\| ".join(json.dumps(v) for v in node["enum"])
    kind = node.get("type", "")
    kind = " or ".join(kind) if isinstance(kind, list) else kind
    if kind == "array" and isinstance(node.get("items"), Mapping):
        inner = _type(node["items"])
        kind = f"list of {inner}" if inner else "list"
    bounds = [
        f"{op} {node[key]}"
        for key, op in (
            ("minimum", "≥"),
            ("exclusiveMinimum", ">"),
            ("maximum", "≤"),
            ("exclusiveMaximum", "<"),
        )
        if key in node
    ]
    return kind + (f" ({', '.join(bounds)})" if bounds else "")


def _value(value: Any) -> str:
    if value is None:
        return "null"
    text = json.dumps(value, ensure_ascii=False)
    return f"`{text}`" if len(text) <= 60 else f"`{text[:57]}...`"


def _rows(
    node: Mapping[str, Any], root: Mapping[str, Any], path: str, config: Any
) -> Iterator[tuple[str, str, str, str, str]]:
    node = _resolve(node, root)
    props = dict(node.get("properties") or {})
    for branch in node.get("allOf", []):  # keys that exist under a condition (a corpus's kind)
        for key, sub in (branch.get("then") or {}).get("properties", {}).items():
            if isinstance(sub, Mapping) and key not in props:
                props[key] = sub
    for key, sub in props.items():
        sub = _resolve(sub, root)
        here = f"{path}.{key}" if path else key
        value = config.get(key, "—") if isinstance(config, Mapping) else "—"
        described = " ".join(str(sub.get("description", "")).split())
        default = _value(sub["default"]) if "default" in sub else ""
        shown = _value(value) if value != "—" and not isinstance(value, Mapping) else ""
        yield here, _type(sub), default, shown, described
        if sub.get("properties") or sub.get("allOf"):
            yield from _rows(sub, root, here, value if isinstance(value, Mapping) else {})
        extra = sub.get("additionalProperties")
        if isinstance(extra, Mapping) and (
            _resolve(extra, root).get("properties") or _resolve(extra, root).get("allOf")
        ):
            yield from _rows(extra, root, f"{here}.<name>", {})


def reference(schema: Mapping[str, Any], config: Mapping[str, Any]) -> str:
    """The page: one table per top-level section, one row per key."""
    out = [HEADER]
    for section, node in schema["properties"].items():
        node = _resolve(node, schema)
        about = " ".join(str(node.get("description", "")).split())
        out.append(f"\n## `{section}`\n")
        if about:
            out.append(f"\n{about}\n")
        rows = list(_rows({"properties": {section: node}}, schema, "", config))
        out.append(
            "\n| key | type | default | config.yaml | meaning |\n| --- | --- | --- | --- | --- |\n"
        )
        for key, kind, default, value, text in rows:
            cells = [f"`{key}`", kind, default, value, text]
            out.append(
                "| " + " | ".join(c.replace("|", "\\|") if c is text else c for c in cells) + " |\n"
            )
    return "".join(out)


def schema_json(schema_path: Path) -> str:
    """The schema's JSON copy (`tacgen_lib.io.config.load_schema` reads it where its
    source_sha256 is the YAML's: parsing the YAML costs a job ~30 ms, the copy ~0.3 ms)."""
    raw = schema_path.read_bytes()
    copy = {"source_sha256": hashlib.sha256(raw).hexdigest(), "schema": load_yaml(schema_path)}
    return json.dumps(copy, separators=(",", ":")) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="exit 1 if a page is out of date")
    args = parser.parse_args(argv)
    schema_path = ROOT / "config" / "config.schema.yaml"
    pages = {
        ROOT / "config" / "README.md": reference(
            load_yaml(schema_path), load_yaml(ROOT / "config" / "config.yaml")
        ),
        schema_copy(schema_path): schema_json(schema_path),
    }
    if args.check:
        stale = [t for t, page in pages.items() if not t.exists() or t.read_text() != page]
        for target in stale:
            print(f"{target} is out of date: run python tools/config_reference.py", file=sys.stderr)
        return 1 if stale else 0
    for target, page in pages.items():
        target.write_text(page)
        print(f"wrote {target}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
