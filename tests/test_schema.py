"""The scenario schema is the core's: Python's models are built from ``_core.scenario_schema()``
and agree with it key for key (defaults, ranges, allowed values, descriptions), and the
core's resolution of a scenario is Python's."""

from __future__ import annotations

import json
import re
import typing

import pytest

import hilcontact as hc
from hilcontact import scenario as sc

core = pytest.importorskip("hilcontact._core")

SCHEMA = json.loads(core.scenario_schema())

MINIMAL = {
    "name": "minimal",
    "simulation": {"duration": 1.0, "period": 0.001},
    "servicer": {"mass": 10.0, "inertia": [1.0, 2.0, 3.0]},
    "target": {"mass": 20.0, "inertia": [[4.0, 0.0, 0.0], [0.0, 5.0, 0.0], [0.0, 0.0, 6.0]]},
    "rod": {"tip": [0.5, 0.0, 0.0]},
    "walls": [{"point": [0.6, 0.0, 0.0], "normal": [-2.0, 0.0, 0.0]}],
    "contact": {"stiffness": 1e5},
}


def deref(prop: dict) -> dict:
    if "$ref" in prop:
        name = prop["$ref"].rsplit("/", 1)[-1]
        return {**SCHEMA["$defs"][name], **{k: v for k, v in prop.items() if k != "$ref"}}
    return prop


def tables():
    """(label, core schema of the table, Python model) for every table and compensator kind."""
    yield "scenario", SCHEMA, hc.Scenario
    for key, prop in SCHEMA["properties"].items():
        schema = deref(prop)
        if schema.get("type") == "array":
            schema = deref(schema["items"])
        if "oneOf" in schema and "properties" in schema["oneOf"][0]:
            for variant in schema["oneOf"]:
                kind = variant["properties"]["kind"]["const"]
                yield f"compensator kind {kind}", variant, sc.COMPENSATOR_MODELS[kind]
        elif "properties" in schema:
            yield key, schema, sc._TABLES[key]


def python_default(field):
    if field.default_factory is not None:
        value = field.default_factory()
        return value.model_dump(mode="json") if hasattr(value, "model_dump") else value
    return field.default


def bounds(field) -> dict:
    out = {}
    for item in field.metadata:
        for name in ("ge", "gt", "le", "lt"):
            if getattr(item, name, None) is not None:
                out[name] = getattr(item, name)
    return out


@pytest.mark.parametrize(("label", "schema", "model"), list(tables()), ids=lambda x: x if isinstance(x, str) else "")
def test_python_models_are_the_core_schema(label, schema, model):
    properties = schema["properties"]
    assert list(model.model_fields) == list(properties), label
    required = set(schema.get("required", ()))
    for name, prop in properties.items():
        field = model.model_fields[name]
        prop = deref(prop)
        where = f"{label}.{name}"
        assert field.is_required() == (name in required and name != "kind"), where
        if "default" in prop:
            assert python_default(field) == prop["default"], where
        if name != "kind":
            assert field.description == " ".join(prop["description"].split()), where
        expected = {
            op: prop[key]
            for key, op in (("minimum", "ge"), ("exclusiveMinimum", "gt"), ("maximum", "le"), ("exclusiveMaximum", "lt"))
            if key in prop
        }
        if prop.get("type") == "integer" and "maximum" not in prop and prop.get("format") in ("uint32", "uint64"):
            expected["le"] = 2 ** int(prop["format"][4:]) - 1  # the core's unsigned type
        assert bounds(field) == expected, where
        choices = [v["const"] for v in prop.get("oneOf", []) if "const" in v] or prop.get("enum")
        if choices and prop.get("type", "string") == "string" and name != "kind":
            assert list(typing.get_args(field.annotation)) == choices, where


def test_minimal_scenario_resolves_as_in_the_core():
    python = hc.Scenario.from_dict(MINIMAL).to_dict()
    rust = json.loads(core.resolve_scenario(json.dumps(MINIMAL)))
    assert python == rust
    # every default of the schema is filled in
    assert python["facility"] == SCHEMA["properties"]["facility"]["default"]
    assert python["metrics"] == SCHEMA["properties"]["metrics"]["default"]
    assert python["compensator"] == SCHEMA["properties"]["compensator"]["default"]


@pytest.mark.parametrize("kind", list(sc.COMPENSATOR_MODELS))
def test_each_kind_resolves_as_in_the_core(kind):
    data = {**MINIMAL, "compensator": {"kind": kind}}
    assert hc.Scenario.from_dict(data).to_dict() == json.loads(core.resolve_scenario(json.dumps(data)))


def test_core_problems_are_all_reported_with_their_keys():
    data = json.loads(json.dumps(MINIMAL))
    data["walls"].append({"name": "wall0", "point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 0.0]})
    data["servicer"]["orientation"] = [0.0, 0.0, 0.0, 0.0]
    data["facility"] = {"robot_delay": 0.0125}
    with pytest.raises(hc.ScenarioError) as info:
        hc.Scenario.from_dict(data)
    keys = [key for key, _ in info.value.issues]
    assert keys == ["servicer.orientation", "walls[1].name", "walls[1].normal", "facility.robot_delay"]
    assert str(info.value).startswith("servicer.orientation: must be a nonzero quaternion")
    assert str(info.value).endswith("(and 3 more: walls[1].name, walls[1].normal, facility.robot_delay)")


def test_python_range_errors_carry_issues():
    with pytest.raises(hc.ScenarioError) as info:
        hc.load_scenario("paper-table1", {"servicer.mass": -1, "compensator.kind": "pic", "compensator.forgetting": 2})
    assert info.value.issues == [
        ("servicer.mass", "must be between 0.001 and 1e7, got -1"),
        ("compensator.forgetting", "must be between 0 and 1 (exclusive), got 2"),
    ]


def test_docs_table_names_every_key():
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "docs" / "scenario.md").read_text(encoding="utf-8")
    missing = [
        f"{label}.{name}"
        for label, schema, _ in tables()
        for name in schema["properties"]
        if not any(form in text for form in (f"| `{name}` |", f"`[{name}]`", f"`[[{name}]]`"))
    ]
    assert not missing, f"docs/scenario.md does not describe {missing}"


def test_docs_table_lists_every_upper_bound():
    """Each key's row in docs/scenario.md says its schema's upper bound (``maximum``, and the
    ``x-magnitude`` of vectors, quaternions and inertias)."""
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "docs" / "scenario.md").read_text(encoding="utf-8")

    def forms(x: float) -> set[str]:
        mantissa, exponent = f"{x:e}".split("e")
        return {f"{x:g}", f"{mantissa.rstrip('0').rstrip('.')}e{int(exponent)}"}

    missing = []
    for label, schema, _ in tables():
        for name, prop in schema["properties"].items():
            prop = deref(prop)
            for key in ("maximum", "x-magnitude"):
                if key not in prop:
                    continue
                rows = [re.split(r"(?<!\\)\|", line)[4] for line in text.splitlines() if line.startswith(f"| `{name}` |")]
                if not any(form in row for row in rows for form in forms(prop[key])):
                    missing.append(f"{label}.{name} {key} {prop[key]}")
    assert not missing, f"docs/scenario.md does not state {missing}"
