"""The real-time flags built from the options' JSON Schema (hilcontact.cli.realtime_flags), on
a small hand-written schema of the shape ``_core.realtime_schema()`` exports."""

from __future__ import annotations

import click
import pytest
from click.testing import CliRunner

from hilcontact.cli.realtime_flags import flags_from_schema, options_from_flags
from hilcontact.errors import RealtimeOptionError

#: A section "toy" (no flags or flat keys of earlier versions), of the shape of the real ones.
SCHEMA = {
    "toy": {
        "type": "object",
        "properties": {
            "sensor": {"description": "The sensor link.", "$ref": "#/$defs/SensorOptions"},
            "limits": {"description": "Safety limits.", "$ref": "#/$defs/Limits"},
            "timeout": {"description": "Longest wait, s (> 0) (CLI `--timeout`).", "type": "number",
                        "exclusiveMinimum": 0.0, "maximum": 10.0, "default": 5.0},
            "mode": {"description": "How.", "$ref": "#/$defs/Mode", "default": "fast"},
            "lock": {"description": "Lock the memory.", "type": "boolean", "default": True},
            "origin": {"description": "Origin, mm.", "type": "array", "items": {"type": "number"},
                       "minItems": 3, "maxItems": 3, "default": [0.0, 0.0, 0.0]},
            "count": {"description": "How many.", "type": ["integer", "null"], "minimum": 1, "default": None},
            "mcap": {"anyOf": [{"$ref": "#/$defs/Limits"}, {"type": "null"}], "default": None},
            "table": {"description": "Not a flag: a list of lists.", "type": "array",
                      "items": {"type": "array", "items": {"type": "number"}}},
        },
        "$defs": {
            "SensorOptions": {"oneOf": [
                {"type": "object", "properties": {
                    "kind": {"type": "string", "const": "aa"},
                    "host": {"description": "Host.", "type": "string", "default": "127.0.0.1"},
                    "port": {"description": "Port.", "type": "integer", "minimum": 0, "maximum": 65535, "default": 1},
                    "gain": {"description": "Gain (> 0).", "type": "number", "exclusiveMinimum": 0.0, "default": 2.0},
                }},
                {"type": "object", "properties": {
                    "kind": {"type": "string", "const": "bb"},
                    "host": {"description": "Host.", "type": "string", "default": "127.0.0.1"},
                    "port": {"description": "Port.", "type": "integer", "minimum": 0, "maximum": 65535, "default": 2},
                }},
            ]},
            "Limits": {"type": "object", "properties": {
                "force_limit": {"description": "Largest force, N.", "type": "number", "default": 500.0},
            }},
            "Mode": {"oneOf": [{"type": "string", "const": "fast"}, {"type": "string", "const": "slow"}]},
        },
    },
}


def command(flags):
    """A command taking the flags and returning their options."""
    @click.command()
    def run(**kw):
        click.echo(repr(options_from_flags("toy", flags, kw)))

    for flag in reversed(flags):
        run = flag.option(run)
    return run


def test_each_option_is_one_flag_named_typed_and_documented_from_the_schema():
    flags = flags_from_schema("toy", SCHEMA)
    assert [f.name for f in flags] == [
        "--sensor-host", "--sensor-port", "--aa-gain", "--force-limit", "--timeout", "--mode", "--no-lock",
        "--origin", "--count",
    ]
    assert {f.name: f.path for f in flags}["--aa-gain"] == ("sensor", "aa", "gain")
    helps = {f.name: f.option(lambda: None).__click_params__[0].help for f in flags}
    assert helps["--timeout"] == "Longest wait, s (> 0). [default: 5]"
    assert helps["--sensor-port"] == "Port. [default: the protocol's: AA 1, BB 2]"
    assert helps["--sensor-host"] == "Host. [default: 127.0.0.1]"
    assert helps["--origin"] == "Origin, mm. [default: 0,0,0]"
    assert helps["--no-lock"] == "Turn off (on by default): Lock the memory."


def test_the_flags_make_the_grouped_options():
    flags = flags_from_schema("toy", SCHEMA)
    result = CliRunner().invoke(command(flags), [
        "--sensor-port", "7", "--aa-gain", "3", "--force-limit", "100", "--timeout", "2", "--mode", "slow",
        "--no-lock", "--origin", "1,2,3", "--count", "4",
    ])
    assert result.exit_code == 0, result.output
    assert eval(result.output) == {
        "sensor": {"port": 7, "kind": "aa", "gain": 3.0}, "limits": {"force_limit": 100.0}, "timeout": 2.0,
        "mode": "slow", "lock": False, "origin": [1.0, 2.0, 3.0], "count": 4,
    }
    assert eval(CliRunner().invoke(command(flags), []).output) == {}  # nothing given: the defaults


@pytest.mark.parametrize(("args", "fragment"), [
    (["--timeout", "nan"], "finite"),
    (["--timeout", "11"], "<= 10"),
    (["--sensor-port", "70000"], "0<=x<=65535"),
    (["--count", "0"], "x>=1"),
    (["--mode", "medium"], "'medium'"),
])
def test_the_schema_ranges_and_choices_are_checked(args, fragment):
    result = CliRunner().invoke(command(flags_from_schema("toy", SCHEMA)), args)
    assert result.exit_code == 2 and fragment in result.output, result.output


def test_a_protocols_option_implies_it_and_is_refused_with_another():
    flags = flags_from_schema("toy", SCHEMA)
    gain = {"opt_aa_gain": 3.0}
    assert options_from_flags("toy", flags, dict(gain), {"sensor": {"kind": "aa"}})["sensor"] == {"kind": "aa", "gain": 3.0}
    with pytest.raises(RealtimeOptionError, match="--aa-gain belongs to sensor kind 'aa', not 'bb'"):
        options_from_flags("toy", flags, dict(gain), {"sensor": {"kind": "bb"}})
    with pytest.raises(RealtimeOptionError, match="--origin"):
        options_from_flags("toy", flags, {"opt_origin": "1,2"})


def test_the_real_schema_keeps_every_historical_flag(core):
    names = {f.name for f in flags_from_schema("runtime")}
    assert {"--force-limit", "--egm-port", "--egm-offset", "--sensor-port", "--counts-per-force", "--rt-priority",
            "--no-lock-memory", "--robot-port", "--sensor", "--robot", "--offset", "--cpu"} <= names
    assert {"--bind-host", "--egm-host", "--egm-local-port", "--silence-sensor-after"} <= {
        f.name for f in flags_from_schema("facility")}
