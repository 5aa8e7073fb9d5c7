"""Each setting stated once: config/config.schema.yaml is the one place a setting's default
lives (the workflow fills it in: `tacgen_lib.workflow_config.validate_config`; config/README.md
is written from it), so nothing else restates one.

- The code gives no schema setting a default of its own (`restated_defaults`): no function
  parameter or class field with a default whose name is a key the schema gives a default, no
  ``.get("<key>", <default>)`` (nor ``.setdefault`` / ``.pop`` with one) and no
  ``.get("<key>") or <literal>`` of such a key. A function takes the settings object or the
  validated config and reads the value; a default there is a second statement that drifts from
  the schema's (a ``label_draws: int = 1`` beside the schema's 3). The scan reads tacgen_lib,
  workflow/scripts, tools and benchmarks with `ast`. A same-named key that is not the setting
  is allowed in `ALLOWED`, file by file, each with its reason. The rules (rules/*.smk, Snakefile) are not
  read yet: `snakemake.parser.parse` turns a rule file into Python that the same scan reads,
  once their Python has moved into the library.
- config/config.yaml states what the embedded default chooses (`stated_defaults`): a value
  equal to the schema's default is written only where the schema requires the key or where
  `STATED_ON_PURPOSE` says why.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import pytest

from tacgen_lib.io.config import load_yaml

ROOT = Path(__file__).resolve().parents[1]
SCHEMA = load_yaml(ROOT / "config" / "config.schema.yaml")
#: the code the scan reads (the rules' Python is not read yet: see the module docstring)
SCANNED = ("tacgen_lib", "workflow", "tools", "benchmarks")

#: file -> {name: why that name there is not the schema's setting of that name}
ALLOWED: dict[str, dict[str, str]] = {
    # config/scenes.yaml's keys, not the config's
    "tacgen_lib/corpus/sim/scenes.py": {
        "kind": "a scene's kind",
        "sensors": "a scene's sensors",
        "shapes": "a scene's shapes",
        "timestep": "a scene's timestep",
        "size": "a scene's gel size",
    },
    # a corpus's name (not transfer.corpus): an ingested corpus's, and ids_in_split's filter
    "tacgen_lib/corpus/ingest.py": {"corpus": "an ingested corpus's name, its kind's"},
    "tacgen_lib/corpus/ingest_hct.py": {"corpus": "an ingested corpus's name, hct"},
    "tacgen_lib/corpus/ingest_ssvtp.py": {"corpus": "an ingested corpus's name, ssvtp"},
    "tacgen_lib/corpus/splits.py": {"corpus": "the corpus whose ids ids_in_split returns"},
    # the alignment heads' widths, no setting (features.pretrain's are DINO's head)
    "tacgen_lib/align/heads.py": {"hidden_dim": "the heads' width", "out_dim": "their output"},
    # torch.optim.AdamW's own signature and defaults (tests/test_optim.py holds the two equal);
    # every caller passes its settings' lr and weight decay
    "tacgen_lib/optim.py": {"lr": "AdamW's signature", "weight_decay": "AdamW's signature"},
    # DINOv2's ViT constructor; a checkpoint's spec passes num_register_tokens
    # (features.backbones.make_backbone)
    "tacgen_lib/features/vit.py": {"num_register_tokens": "DINOv2's ViT signature"},
    # the logistic probe's solver: class labels and iteration caps (not transfer.classes, a
    # count, nor probes.robustness.mlp.max_iter)
    "tacgen_lib/probes/batched.py": {"classes": "class labels", "max_iter": "solver caps"},
    "tacgen_lib/probes/objective.py": {"classes": "class labels"},
    "tacgen_lib/probes/logistic.py": {"max_iter": "the L-BFGS cap"},
    # given CV folds (index arrays), not a fold count
    "tacgen_lib/probes/ridge_cv.py": {"folds": "the folds' index arrays"},
    # the transfer table's columns (not policy.heads_from / heads_seed)
    "tacgen_lib/probes/transfer.py": {
        "heads_from": "view -> the corpus of its heads",
        "heads_seed": "the alignment seed of the rows, as text",
    },
    # the name of the config or edge in an error message (not transfer.source)
    "tacgen_lib/io/config.py": {"source": "the config's name in an error"},
    "tacgen_lib/workflow_config.py": {"source": "the config's name in an error"},
    "tacgen_lib/generate/baselines.py": {"source": "the edge's name in an error"},
    # a job's threads as Snakemake gives them (not features.threads)
    "tacgen_lib/estimate/dag.py": {"threads": "a DAG job's threads"},
    "tacgen_lib/estimate/schedule.py": {"threads": "a scheduled task's threads"},
}

#: keys of config/config.yaml that state the schema's default on purpose (dotted):
#: the policy stage's sizes and grid and the transfer's probe seeds, which a user scaling the
#: run changes first (each beside the paper's value), and the regime's labelled sizes beside
#: its pool sizes and seeds. A key the schema requires is written anyway (`stated_defaults`).
STATED_ON_PURPOSE = {
    "regime.n_labelled",
    "policy.n_demos",
    "policy.n_heldout",
    "policy.seeds",
    "policy.sweep_epochs",
    "policy.sweep_seeds",
    "transfer.probe_seeds",
}


# --------------------------------------------------------------------------- the schema


def _definition(node: Mapping[str, Any], value: Any) -> dict[str, Any]:
    """`node` with its ``$ref`` followed and the ``then`` of each ``allOf`` branch whose
    ``kind`` condition `value` meets merged in (the corpus definitions)."""
    while "$ref" in node:
        ref = SCHEMA["$defs"][node["$ref"].split("/")[-1]]
        node = {**ref, **{k: v for k, v in node.items() if k != "$ref"}}
    out = {**node, "properties": dict(node.get("properties") or {})}
    out["required"] = list(node.get("required") or [])
    kind = value.get("kind") if isinstance(value, Mapping) else None
    for branch in node.get("allOf", []):
        cond = branch.get("if", {}).get("properties", {}).get("kind", {})
        if kind is not None and (kind == cond.get("const") or kind in cond.get("enum", [])):
            then = _definition(branch["then"], value)
            out["properties"].update(then["properties"])
            out["required"] += then["required"]
    return out


def schema_settings(node: Any = SCHEMA) -> set[str]:
    """Names of the keys the schema gives a default, sections (a key with keys of its own,
    whose settings are those keys) left out."""
    names: set[str] = set()
    if not isinstance(node, Mapping):
        return names
    for key, sub in (node.get("properties") or {}).items():
        if isinstance(sub, Mapping) and "default" in sub and "properties" not in sub:
            names.add(key)
        names |= schema_settings(sub)
    for key in ("additionalProperties", "items", "then"):
        names |= schema_settings(node.get(key))
    for sub in [*node.get("allOf", []), *node.get("anyOf", [])]:
        names |= schema_settings(sub)
    for sub in (node.get("$defs") or {}).values():
        names |= schema_settings(sub)
    return names


SETTINGS = schema_settings()


# --------------------------------------------------------------------------- the code scan

#: a Snakemake job's files (``snakemake.input.get("extract", [])``): not the config
_JOB_FILES = {"input", "output", "log"}


def _literal(node: ast.expr) -> bool:
    try:
        ast.literal_eval(node)
    except (ValueError, TypeError, SyntaxError, MemoryError, RecursionError):
        return False
    return True


def _key_of(call: ast.expr, n_args: int) -> str | None:
    """The setting a ``<mapping>.get / setdefault / pop("<key>", ...)`` call with `n_args`
    arguments reads, if its key is one (a Snakemake job's files are not the config)."""
    if not (
        isinstance(call, ast.Call)
        and isinstance(call.func, ast.Attribute)
        and call.func.attr in ("get", "setdefault", "pop")
        and len(call.args) == n_args
        and isinstance(call.args[0], ast.Constant)
        and call.args[0].value in SETTINGS
    ):
        return None
    owner = call.func.value
    if isinstance(owner, ast.Attribute) and owner.attr in _JOB_FILES:
        return None
    return str(call.args[0].value)


def _field_default(value: ast.expr | None) -> bool:
    """Whether a class field's value is a default of its own: a literal, or
    ``field(default=<literal>)`` (not `io.schema.setting`, which reads the schema's)."""
    if value is None:
        return False
    if isinstance(value, ast.Call) and getattr(value.func, "id", None) == "field":
        return any(k.arg == "default" and _literal(k.value) for k in value.keywords)
    return _literal(value)


def restated_defaults(source: str) -> Iterator[tuple[int, str, str]]:
    """(line, setting, what) of every default the code `source` gives a schema setting."""
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda):
            a = node.args
            positional = [*a.posonlyargs, *a.args]
            pairs = list(
                zip(positional[len(positional) - len(a.defaults) :], a.defaults, strict=True)
            )
            pairs += [
                (k, d) for k, d in zip(a.kwonlyargs, a.kw_defaults, strict=True) if d is not None
            ]
            for arg, default in pairs:
                if arg.arg in SETTINGS:
                    yield default.lineno, arg.arg, f"parameter default {ast.unparse(default)}"
        elif isinstance(node, ast.ClassDef):
            for st in node.body:
                if (
                    isinstance(st, ast.AnnAssign)
                    and isinstance(st.target, ast.Name)
                    and st.target.id in SETTINGS
                    and _field_default(st.value)
                ):
                    yield st.lineno, st.target.id, f"field default {ast.unparse(st.value)}"
        elif isinstance(node, ast.Call) and (key := _key_of(node, 2)):
            yield node.lineno, key, ast.unparse(node)
        elif (
            isinstance(node, ast.BoolOp)
            and isinstance(node.op, ast.Or)
            and (key := _key_of(node.values[0], 1))
            and _literal(node.values[1])
        ):
            yield node.lineno, key, ast.unparse(node)


def _code() -> list[Path]:
    return sorted(p for d in SCANNED for p in (ROOT / d).rglob("*.py"))


def rule_file_python(path: Path) -> tuple[str, dict[int, int]]:
    """A Snakefile or rules/*.smk file as the Python Snakemake compiles it to (its own parser),
    with the map from the compiled lines back to the file's."""
    import tempfile
    from types import SimpleNamespace

    import snakemake.api  # noqa: F401 - the parser's imports need the API loaded first
    from snakemake.parser import parse
    from snakemake.sourcecache import SourceCache, infer_source_file

    with tempfile.TemporaryDirectory() as cache:
        workflow = SimpleNamespace(sourcecache=SourceCache(Path(cache)), linemaps={})
        linemap: dict[int, int] = {}
        code, _ = parse(infer_source_file(str(path)), workflow, linemap)
    return code, linemap


def _rule_files() -> list[Path]:
    return [ROOT / "Snakefile", *sorted((ROOT / "rules").glob("*.smk"))]


def _findings() -> list[tuple[str, int, str, str]]:
    found = [
        (str(path.relative_to(ROOT)), line, key, what)
        for path in _code()
        for line, key, what in restated_defaults(path.read_text())
    ]
    for path in _rule_files():
        code, linemap = rule_file_python(path)
        found += [
            (str(path.relative_to(ROOT)), linemap.get(line, line), key, what)
            for line, key, what in restated_defaults(code)
        ]
    return found


def test_no_code_restates_a_schema_default():
    bad = [f for f in _findings() if f[2] not in ALLOWED.get(f[0], {})]
    lines = [f"{path}:{line}: {key}: {what}" for path, line, key, what in bad]
    assert not bad, (
        "a schema setting given a default of its own (read it from the settings object or "
        "the validated config; config/config.schema.yaml states its default):\n" + "\n".join(lines)
    )


def test_every_allowed_name_is_still_there():
    found = {(path, key) for path, _, key, _ in _findings()}
    stale = sorted({(p, k) for p, names in ALLOWED.items() for k in names} - found)
    assert not stale, f"ALLOWED entries the code no longer has (remove them): {stale}"


def test_the_scan_finds_what_a_restated_default_looks_like():
    """The forms the scan knows, on a setting of the schema (regime.label_draws, default 3):
    each flagged; the forms that read the schema's value are not."""
    restated = """
from dataclasses import dataclass, field

def evaluate(sets, *, label_draws: int = 1): ...
def job(cfg): return cfg["regime"].get("label_draws", 1)
def job2(cfg): return cfg["regime"].get("label_draws") or 3
def job3(cfg): cfg["regime"].setdefault("label_draws", 3)
pick = lambda label_draws=3: label_draws

@dataclass
class Draws:
    label_draws: int = 3
    knn_ks: tuple = field(default=(1, 2))
"""
    found = sorted((line, key) for line, key, _ in restated_defaults(restated))
    assert found == [
        (4, "label_draws"),
        (5, "label_draws"),
        (6, "label_draws"),
        (7, "label_draws"),
        (8, "label_draws"),
        (12, "label_draws"),
        (13, "knn_ks"),
    ]
    read = """
from tacgen_lib.io.schema import setting

def evaluate(sets, regime): return regime.label_draws
def job(cfg): return cfg["regime"]["label_draws"], cfg["regime"].get("label_draws")
def files(snakemake): return snakemake.output.get("features", [])
def other(cfg, name): return cfg.get(name, 1), cfg.get("label_draws") or cfg["x"]

class Draws:
    label_draws: int = setting("regime.label_draws")
    n: int
"""
    assert list(restated_defaults(read)) == []


# --------------------------------------------------------------------------- config.yaml


def _same(a: Any, b: Any) -> bool:
    """Equal values of equal types (a YAML 1 is not the schema's 1.0: it would not be the same
    validated config)."""
    if isinstance(a, Mapping) and isinstance(b, Mapping):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list | tuple) and isinstance(b, list | tuple):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    return type(a) is type(b) and a == b


def stated_defaults(config: Mapping[str, Any], node: Mapping[str, Any] = SCHEMA, at: str = ""):
    """Dotted keys of `config` whose value is the schema's default for that key (a key the
    schema requires left out: it is written whatever its value)."""
    node = _definition(node, config)
    extra = node.get("additionalProperties")
    for key, value in config.items():
        sub = node["properties"].get(key, extra if isinstance(extra, Mapping) else {})
        sub = _definition(sub, value)
        where = f"{at}.{key}" if at else str(key)
        if "default" in sub and key not in node["required"] and _same(value, sub["default"]):
            yield where
        elif isinstance(value, Mapping):
            yield from stated_defaults(value, sub, where)


def test_the_embedded_default_states_only_its_choices():
    config = load_yaml(ROOT / "config" / "config.yaml")
    restated = [k for k in stated_defaults(config) if k not in STATED_ON_PURPOSE]
    assert not restated, (
        "config/config.yaml states the schema's default of these keys (drop them, or say in "
        f"STATED_ON_PURPOSE why the file must show them): {restated}"
    )


def test_every_key_stated_on_purpose_is_stated():
    stated = set(stated_defaults(load_yaml(ROOT / "config" / "config.yaml")))
    assert STATED_ON_PURPOSE <= stated, f"not stated (remove): {STATED_ON_PURPOSE - stated}"


@pytest.mark.parametrize(
    ("config", "want"),
    [
        ({"regime": {"label_draws": 3, "n_pool": [1024]}}, ["regime.label_draws"]),
        ({"regime": {"label_draws": 3.0}}, []),  # not the schema's integer 3
        ({"align": {"epochs": 300, "seeds": [42]}}, ["align.epochs"]),
        # kind and shards are required keys of a simulated corpus, presses is not
        (
            {"corpora": {"c": {"kind": "simulated", "shards": 1, "presses": 8, "n": 5}}},
            ["corpora.c.presses"],
        ),
        ({"features": {"mae": {"epochs": 10, "lr": 0.01}}}, ["features.mae.epochs"]),
    ],
)
def test_the_config_scan_finds_a_value_equal_to_the_default(config, want):
    assert list(stated_defaults(config)) == want


def test_the_scan_reads_the_rule_files_as_snakemake_compiles_them(tmp_path):
    smk = tmp_path / "a.smk"
    smk.write_text(
        'LANGUAGE = config["language"]\n\n\n'
        "rule r:\n"
        "    params:\n"
        '        draws=config["regime"].get("label_draws", 1),\n'
        '    shell:\n        "true"\n'
    )
    code, linemap = rule_file_python(smk)
    found = [(linemap.get(line, line), key) for line, key, _ in restated_defaults(code)]
    assert found == [(6, "label_draws")]
    assert len(_rule_files()) > 20, "the Snakefile and every rules/*.smk are scanned"
