"""Scenario loading, validation messages, overrides, delay rounding, TOML round trip."""

from __future__ import annotations

import json
import tomllib
from importlib import resources

import numpy as np
import pytest
import tomli_w

import hilcontact as hc
from hilcontact.scenario import apply_overrides, preset_names

PRESET = "paper-table1"


def raw_preset(name: str = PRESET) -> dict:
    text = resources.files("hilcontact").joinpath("scenarios", f"{name}.toml").read_text(encoding="utf-8")
    return tomllib.loads(text)


def error_of(source=PRESET, overrides=None) -> str:
    with pytest.raises(hc.ScenarioError) as info:
        hc.load_scenario(source, overrides)
    message = str(info.value)
    assert "\n" not in message, f"error message must be one line: {message!r}"
    assert isinstance(info.value, ValueError)
    return message


# ---- presets ------------------------------------------------------------------------------


def test_presets_lists_embedded_files_with_descriptions():
    listing = hc.presets()
    files = sorted(
        entry.name[:-5]
        for entry in resources.files("hilcontact").joinpath("scenarios").iterdir()
        if entry.name.endswith(".toml")
    )
    assert sorted(listing) == files == preset_names()
    assert PRESET in listing
    assert listing[PRESET] == raw_preset()["description"]
    assert listing[PRESET].startswith("Paper Table 1")
    assert all(isinstance(d, str) and d for d in listing.values())


def test_paper_table1_values_are_resolved():
    s = hc.load_scenario(PRESET)
    assert s.name == PRESET
    assert s.simulation.duration == 5.5 and s.simulation.period == 0.001
    assert s.simulation.divergence_energy_ratio == 100.0  # default filled in
    assert s.servicer.mass == 300.0 and s.target.mass == 4000.0
    assert s.servicer.inertia == [[98.0, 0.0, 0.0], [0.0, 98.0, 0.0], [0.0, 0.0, 98.0]]
    assert s.target.inertia[1][1] == 3684.0 and s.target.inertia[0][1] == 0.0
    assert s.servicer.velocity == [0.02, 0.0, 0.0]
    assert s.target.orientation == [1.0, 0.0, 0.0, 0.0]
    assert [w.name for w in s.walls] == ["front", "rear"]
    assert s.walls[0].normal == [-1.0, 0.0, 0.0]
    assert s.contact.model == "linear" and s.contact.stiffness == 176275.0 and s.contact.exponent == 1.5
    assert s.facility.robot_delay == 0.010 and s.facility.sensor_delay == 0.0
    assert s.facility.servo_damping == 0.7 and s.facility.seed == 1 and s.facility.round_delays is False
    assert s.compensator.kind == "none"
    assert s.metrics.contact_threshold == 0.5


def test_minimal_scenario_gets_all_defaults(scenario_file):
    path = scenario_file(
        """
name = "minimal"
[simulation]
duration = 1
period = 0.001
[servicer]
mass = 10
inertia = [1, 2, 3]
[target]
mass = 20
inertia = [[4, 0, 0], [0, 5, 0], [0, 0, 6]]
[rod]
tip = [0.5, 0, 0]
[[walls]]
point = [0.6, 0, 0]
normal = [-2, 0, 0]
[[walls]]
point = [0, 0.1, 0]
normal = [0, -1, 0]
[contact]
stiffness = 1e5
"""
    )
    s = hc.load_scenario(path)
    assert s.description == ""
    assert s.simulation.duration == 1.0 and isinstance(s.simulation.duration, float)
    assert (s.simulation.plant_substeps, s.simulation.reference_substeps) == (10, 2)
    assert s.servicer.inertia == [[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 3.0]]
    assert s.servicer.position == [0.0, 0.0, 0.0] and s.servicer.angular_velocity == [0.0, 0.0, 0.0]
    assert s.servicer.orientation == [1.0, 0.0, 0.0, 0.0]
    assert [w.name for w in s.walls] == ["wall0", "wall1"]
    assert s.walls[0].normal == [-1.0, 0.0, 0.0]  # normalised
    assert s.contact.model == "linear" and s.contact.damping == 0.0 and s.contact.exponent == 1.5
    f = s.facility
    assert (f.robot_delay, f.sensor_delay, f.servo_frequency, f.servo_damping) == (0.0, 0.0, 0.0, 0.7)
    assert (f.sensor_noise, f.torque_noise, f.force_resolution, f.torque_resolution) == (0.0,) * 4
    assert f.sensor_position == [0.0, 0.0, 0.0] and f.sensor_orientation == [1.0, 0.0, 0.0, 0.0]
    assert (f.seed, f.round_delays) == (0, False)
    assert s.compensator.kind == "none" and s.metrics.contact_threshold == 0.5
    # defaults are explicit in the resolved TOML
    resolved = tomllib.loads(s.to_toml())
    assert resolved["facility"]["servo_damping"] == 0.7
    assert resolved["compensator"] == {"kind": "none"}
    assert resolved["walls"][1]["name"] == "wall1"


def test_quaternions_and_normals_are_normalised():
    s = hc.load_scenario(
        PRESET,
        {
            "servicer.orientation": [2.0, 0.0, 0.0, 0.0],
            "target.orientation": [1.0, 1.0, 1.0, 1.0],
            "walls[1].normal": [3.0, 4.0, 0.0],
        },
    )
    assert s.servicer.orientation == [1.0, 0.0, 0.0, 0.0]
    assert s.target.orientation == pytest.approx([0.5, 0.5, 0.5, 0.5], abs=1e-15)
    assert s.walls[1].normal == pytest.approx([0.6, 0.8, 0.0], abs=1e-15)
    assert hc.Scenario.from_toml(s.to_toml()) == s


def test_inertia_matrix_form_is_accepted_and_kept():
    matrix = [[10.0, 1.0, 0.0], [1.0, 12.0, 0.5], [0.0, 0.5, 8.0]]
    s = hc.load_scenario(PRESET, {"servicer.inertia": matrix})
    assert s.servicer.inertia == matrix
    assert json.loads(s.to_json())["servicer"]["inertia"] == matrix


def test_to_json_is_the_resolved_schema():
    data = json.loads(hc.load_scenario(PRESET).to_json())
    assert set(data) == {
        "name", "description", "simulation", "servicer", "target", "rod", "walls",
        "contact", "facility", "compensator", "metrics",
    }
    assert data["target"]["inertia"] == [[3684.0, 0.0, 0.0], [0.0, 3684.0, 0.0], [0.0, 0.0, 3684.0]]
    assert data["walls"][1] == {"name": "rear", "point": [-0.01, 0.0, 0.0], "normal": [1.0, 0.0, 0.0]}
    assert data["compensator"] == {"kind": "none"}
    assert data["facility"]["robot_delay"] == 0.01


# ---- TOML round trip ----------------------------------------------------------------------


@pytest.mark.parametrize("name", preset_names())
def test_toml_round_trip_for_every_preset(name, tmp_path):
    s = hc.load_scenario(name)
    text = s.to_toml()
    again = hc.Scenario.from_toml(text)
    assert again == s
    assert again.to_toml() == text
    assert again.to_json() == s.to_json()
    path = tmp_path / "resolved.toml"
    path.write_text(text, encoding="utf-8")
    assert hc.load_scenario(path) == s
    assert hc.load_scenario(str(path)) == s


def test_round_trip_with_awkward_values():
    s = hc.load_scenario(
        PRESET,
        {
            "servicer.velocity": [0.1 + 0.2, 1e-300, -0.0],
            "target.orientation": [0.3, 0.1, -0.7, 0.2],
            "walls[0].normal": [1.0, 1.0, 1.0],
            "servicer.inertia": [[3.0, 0.1, 0.2], [0.1, 4.0, 0.3], [0.2, 0.3, 5.0]],
            "description": 'quotes " and \\ and\nnewline [x,\n y]',
            "facility.robot_delay": 0.0137,
            "facility.round_delays": True,
        },
    )
    again = hc.Scenario.from_toml(s.to_toml())
    assert again == s
    assert again.to_toml() == s.to_toml()


# ---- delays -------------------------------------------------------------------------------


def test_non_integer_delay_message_matches_spec():
    message = error_of(PRESET, {"facility.robot_delay": 0.0125})
    assert message == (
        "facility.robot_delay = 0.0125 s is not a whole number of periods "
        "(simulation.period = 0.001 s): use 0.012 or 0.013, or set facility.round_delays = true"
    )


def test_non_integer_sensor_delay_is_rejected():
    message = error_of(PRESET, {"facility.sensor_delay": 0.0005})
    assert message.startswith("facility.sensor_delay = 0.0005 s is not a whole number of periods")
    assert "use 0 or 0.001" in message


def test_whole_delays_within_tolerance_are_accepted():
    s = hc.load_scenario(PRESET, {"facility.robot_delay": 0.1 + 0.2 - 0.3 + 0.02, "simulation.period": 0.001})
    assert s.facility.robot_delay == pytest.approx(0.02, abs=1e-15)


@pytest.mark.parametrize(
    ("robot", "sensor", "expected_robot", "expected_sensor"),
    [(0.0126, 0.0049, 0.013, 0.005), (0.0104, 0.0, 0.01, 0.0), (0.0004, 0.0021, 0.0, 0.002)],
)
def test_round_delays_rounds_to_nearest_period(robot, sensor, expected_robot, expected_sensor):
    s = hc.load_scenario(
        PRESET,
        {"facility.robot_delay": robot, "facility.sensor_delay": sensor, "facility.round_delays": True},
    )
    assert s.facility.robot_delay == expected_robot
    assert s.facility.sensor_delay == expected_sensor
    resolved = tomllib.loads(s.to_toml())["facility"]
    assert resolved["robot_delay"] == expected_robot and resolved["round_delays"] is True
    assert json.loads(s.to_json())["facility"]["sensor_delay"] == expected_sensor
    assert hc.Scenario.from_toml(s.to_toml()) == s


def test_round_delays_with_other_period():
    s = hc.load_scenario(
        PRESET,
        {"simulation.period": 0.004, "facility.robot_delay": 0.0101, "facility.round_delays": True},
    )
    assert s.facility.robot_delay == 0.012


# ---- overrides ----------------------------------------------------------------------------


def test_overrides_are_applied_before_validation():
    s = hc.load_scenario(
        PRESET,
        {
            "facility.robot_delay": 0.02,
            "servicer.velocity": [0.01, 0.0, 0.0],
            "name": "custom",
            "contact.damping": 5,
            "walls[0].point": [0.02, 0.0, 0.0],
        },
    )
    assert s.facility.robot_delay == 0.02
    assert s.servicer.velocity == [0.01, 0.0, 0.0]
    assert s.name == "custom"
    assert s.contact.damping == 5.0
    assert s.walls[0].point == [0.02, 0.0, 0.0] and s.walls[1].point == [-0.01, 0.0, 0.0]
    # untouched values survive
    assert s.servicer.mass == 300.0 and s.facility.seed == 1


def test_overrides_create_missing_tables():
    raw = raw_preset()
    assert "metrics" not in raw
    s = hc.load_scenario(PRESET, {"metrics.contact_threshold": 2.0})
    assert s.metrics.contact_threshold == 2.0


def test_override_accepts_numpy_values():
    s = hc.load_scenario(
        PRESET,
        {
            "facility.robot_delay": np.float64(0.004),
            "facility.seed": np.int64(7),
            "servicer.position": np.array([-1.0, 0.0, 0.0]),
        },
    )
    assert s.facility.robot_delay == 0.004 and s.facility.seed == 7 and type(s.facility.seed) is int
    assert s.servicer.position == [-1.0, 0.0, 0.0]


def test_apply_overrides_copies_and_replaces_whole_tables():
    raw = raw_preset()
    out = apply_overrides(raw, {"facility": {"robot_delay": 0.004}, "walls[1].name": "back"})
    assert out["facility"] == {"robot_delay": 0.004}
    assert out["walls"][1]["name"] == "back"
    assert raw["facility"]["robot_delay"] == 0.010 and raw["walls"][1]["name"] == "rear"  # not mutated
    s = hc.load_scenario(raw, {"facility": {"robot_delay": 0.004}})
    assert s.facility.robot_delay == 0.004 and s.facility.seed == 0


def test_scenario_as_source_with_overrides():
    base = hc.load_scenario(PRESET)
    s = hc.load_scenario(base, {"facility.robot_delay": 0.004})
    assert s.facility.robot_delay == 0.004 and base.facility.robot_delay == 0.010


@pytest.mark.parametrize(
    ("overrides", "expected"),
    [
        ({"a..b": 1}, "invalid override key 'a..b'"),
        ({"walls[7].point": [0, 0, 0]}, "walls has only 2 item(s)"),
        ({"name.first": "x"}, "name is not a table"),
        ({"servicer[0]": 1}, "servicer is not a list"),
    ],
)
def test_bad_override_keys(overrides, expected):
    assert expected in error_of(PRESET, overrides)


# ---- bad input ----------------------------------------------------------------------------

BAD_INPUT = [
    # (overrides, exact message or (key, fragment))
    ({"servicer.mas": 1.0}, ("servicer.mas", "unknown key (did you mean 'mass'?); allowed keys in [servicer]: "
                              "mass, inertia, position, orientation, velocity, angular_velocity")),
    ({"facility.delay": 0.01}, ("facility.delay", "allowed keys in [facility]: robot_delay, sensor_delay")),
    ({"walls[1].colour": "red"}, ("walls[1].colour", "allowed keys in [[walls]]: name, point, normal")),
    ({"compensator.gain": 1.0}, ("compensator.gain", "allowed keys in [compensator] with kind = 'none': kind")),
    ({"extra_table.x": 1}, ("extra_table", "unknown top-level key; allowed: name, description, simulation")),
    ({"servicer.mass": 0}, "servicer.mass: must be between 0.001 and 1e7, got 0"),
    ({"target.mass": -4000.0}, "target.mass: must be between 0.001 and 1e7, got -4000.0"),
    ({"simulation.period": 0.0}, "simulation.period: must be between 1e-6 and 1, got 0.0"),
    ({"simulation.duration": -1}, "simulation.duration: must be > 0 and <= 86400, got -1"),
    ({"contact.stiffness": 0}, "contact.stiffness: must be > 0 and <= 1e11, got 0"),
    ({"contact.damping": -1.0}, "contact.damping: must be between 0 and 1e9, got -1.0"),
    ({"facility.robot_delay": -0.001}, "facility.robot_delay: must be between 0 and 60, got -0.001"),
    ({"simulation.plant_substeps": 0}, "simulation.plant_substeps: must be between 1 and 1000, got 0"),
    ({"simulation.divergence_energy_ratio": 1.0}, "simulation.divergence_energy_ratio: must be > 1 and <= 1e12, got 1.0"),
    ({"walls[1].normal": [0, 0, 0]}, ("walls[1].normal", "nonzero")),
    ({"walls[0].normal": [0.0, 0.0]}, "walls[0].normal: expected 3 numbers [x, y, z], got [0.0, 0.0]"),
    ({"simulation.duration": "abc"}, "simulation.duration: expected a number, got 'abc'"),
    ({"servicer.mass": True}, "servicer.mass: expected a number, got true"),
    ({"facility.seed": 1.5}, "facility.seed: expected an integer, got 1.5"),
    ({"facility.seed": -1}, "facility.seed: must be between 0 and 18446744073709551615, got -1"),
    ({"facility.round_delays": "yes"}, "facility.round_delays: expected true or false, got 'yes'"),
    ({"name": 42}, "name: expected a string, got 42"),
    ({"name": "a/b"}, ("name", "without '/'")),
    ({"rod.tip": [1, "x", 0]}, "rod.tip: expected 3 numbers [x, y, z], got [1, 'x', 0]"),
    ({"servicer.position": float("nan")}, ("servicer.position", "expected 3 numbers")),
    ({"facility.sensor_noise": float("inf")}, "facility.sensor_noise: must be a finite number, got inf"),
    ({"servicer.orientation": [0, 0, 0, 0]}, ("servicer.orientation", "nonzero quaternion")),
    ({"facility.sensor_orientation": [1, 0, 0]}, ("facility.sensor_orientation", "quaternion [w, x, y, z]")),
    ({"servicer.inertia": [98.0, 0.0, 98.0]}, ("servicer.inertia", "principal moments must all be >= 1e-6")),
    ({"servicer.inertia": [[1, 2, 0], [0, 1, 0], [0, 0, 1]]}, ("servicer.inertia", "symmetric")),
    ({"servicer.inertia": [[1, 2, 0], [2, 1, 0], [0, 0, 1]]}, ("servicer.inertia", "positive definite")),
    ({"servicer.inertia": "big"}, ("servicer.inertia", "3 principal moments")),
    ({"contact.model": "hertz"}, "contact.model: must be one of 'linear' or 'hunt-crossley', got 'hertz'"),
    ({"compensator.kind": "magic"}, "compensator.kind: unknown compensator kind 'magic'; allowed: 'none', 'pic', "
                                     "'dac', 'pida', 'tdpa-impedance', 'tdpa-admittance', 'model-mediated'"),
    ({"walls": []}, "walls: at least one [[walls]] table (or shapes on both bodies, [[servicer.shapes]] and [[target.shapes]]) is required"),
    ({"walls": "front"}, ("walls", "expected one or more [[walls]] tables")),
    ({"servicer": 3}, "servicer: expected a table, got 3"),
    ({"walls[0].name": "rear"}, ("walls[1].name", "duplicate wall name 'rear'")),
    ({"simulation.duration": 0.0005}, ("simulation.duration", "shorter than one period")),
]


@pytest.mark.parametrize(("overrides", "expected"), BAD_INPUT, ids=[str(list(o)[0]) for o, _ in BAD_INPUT])
def test_bad_values_give_one_clear_line(overrides, expected):
    message = error_of(PRESET, overrides)
    if isinstance(expected, tuple):
        key, fragment = expected
        assert message.startswith((key + ":", key + " =")), message
        assert fragment in message, message
    else:
        assert message == expected


@pytest.mark.parametrize(
    ("table", "key", "expected"),
    [
        ("servicer", "mass", "servicer.mass: missing required value (kg, 0.001 to 1e7)"),
        ("simulation", "period", "simulation.period: missing required value (control period T in s, 1 µs to 1 s)"),
        ("contact", "stiffness", "contact.stiffness: missing required value"),
        ("rod", "tip", "rod.tip: missing required value"),
        (None, "name", "name: missing required value"),
        (None, "target", "target: missing required table [target]"),
        (None, "walls", "walls: at least one [[walls]] table (or shapes on both bodies"),
    ],
)
def test_missing_required_values(table, key, expected):
    raw = raw_preset()
    if table is None:
        del raw[key]
    else:
        del raw[table][key]
    message = error_of(raw)
    assert message.startswith(expected), message


def test_missing_wall_field_names_the_index():
    raw = raw_preset()
    del raw["walls"][1]["normal"]
    assert error_of(raw).startswith("walls[1].normal: missing required value")


def test_several_problems_are_summarised_on_one_line():
    message = error_of(PRESET, {"servicer.mass": -1, "target.mass": "x", "contact.bogus": 1})
    assert message.startswith("servicer.mass: must be between 0.001 and 1e7, got -1 (and 2 more: target.mass, contact.bogus)")


def test_invalid_toml_names_file_and_line(scenario_file):
    path = scenario_file('name = "x"\n[simulation]\nduration = = 3\n', name="broken.toml")
    message = error_of(path)
    assert "broken.toml: invalid TOML" in message
    assert "line 3" in message


def test_unknown_preset_lists_presets():
    message = error_of("no-such-preset")
    assert message.startswith("unknown scenario 'no-such-preset'")
    assert "paper-table1" in message


def test_missing_file_and_directory(tmp_path):
    assert "not a preset and no such file" in error_of(str(tmp_path / "absent.toml"))
    assert "is a directory" in error_of(tmp_path)


def test_not_utf8_file(scenario_file, tmp_path):
    path = tmp_path / "latin.toml"
    path.write_bytes(b'name = "caf\xe9"\n')
    assert "not a UTF-8 text file" in error_of(path)


def test_scenario_error_hierarchy():
    assert issubclass(hc.ScenarioError, hc.HilContactError)
    assert issubclass(hc.ScenarioError, ValueError)


def test_public_api():
    for name in ("presets", "load_scenario", "simulate", "Scenario", "Run", "ScenarioError", "HilContactError"):
        assert name in hc.__all__ and hasattr(hc, name)


# ---- [compensator] parameters ---------------------------------------------------------------

KINDS = ["none", "pic", "dac", "pida", "tdpa-impedance", "tdpa-admittance", "model-mediated"]

MODEL_DEFAULTS = {
    "delay_mode": "align",
    "contact_force": 3.0,
    "stiffness_initial": 1.0e5,
    "damping_initial": 0.0,
    "stiffness_std": 1.0e5,
    "damping_std": 300.0,
    "stiffness_walk": 10.0,
    "damping_walk": 0.1,
    "noise_std": 0.1,
    "forgetting": 0.98,
    "alpha_max": 100000.0,
    "observer": "work",
    "controller": "normal",
    "force_ratio_max": 2.0,
    "pull": False,
}
TDPA_DEFAULTS = {
    "contact_force": 3.0,
    "alpha_max": 100000.0,
    "beta_max": 1e-4,
    "velocity_floor": 1e-3,
    "force_floor": 1.0,
}
DEFAULTS = {
    "none": {},
    "pic": MODEL_DEFAULTS,
    "dac": MODEL_DEFAULTS,
    "pida": MODEL_DEFAULTS,
    "tdpa-impedance": TDPA_DEFAULTS,
    "tdpa-admittance": TDPA_DEFAULTS,
    "model-mediated": {
        "law": "auto",
        "prior_walls": [],
        "correct_priors": True,
        "prior_friction": 0.0,
        "prior_shapes": "none",
        "match_angle": 30.0,
        "gap_tolerance": 1e-3,
        "min_samples": 20,
        "max_samples": 20000,
        "memory": 2000,
        "residual_gain": 0.0,
        "force_ratio_max": 2.0,
        "fallback": MODEL_DEFAULTS,
        # no calibration: no walls (the table is listed, as every parameter is)
        "calibration": {
            "measured": {"scenario": "", "at": "", "facility": "", "version": "", "probes_per_wall": 0,
                         "press_force": 0.0, "duration": 0.0},
            "walls": [],
            "law": {"model": "linear", "stiffness": 1.0, "damping": 0.0, "exponent": 1.0, "stiffness_sigma": 0.0,
                    "damping_sigma": 0.0, "exponent_sigma": 0.0},
            "robot": {"delay": 0.0, "delay_sigma": 0.0, "servo_frequency": 0.0, "servo_damping": 0.0, "sensor_delay": 0.0},
        },
    },
}


def test_compensator_kinds_are_the_cores():
    assert list(hc.scenario.COMPENSATOR_MODELS) == KINDS


@pytest.mark.parametrize("kind", KINDS)
def test_each_kind_parses_with_defaults(kind):
    s = hc.load_scenario(PRESET, {"compensator": {"kind": kind}})
    assert s.compensator.kind == kind
    assert s.to_dict()["compensator"] == {"kind": kind, **DEFAULTS[kind]}
    # the resolved TOML lists every parameter, kind first
    table = tomllib.loads(s.to_toml())["compensator"]
    assert table == {"kind": kind, **DEFAULTS[kind]}
    assert list(table)[0] == "kind"
    assert json.loads(s.to_json())["compensator"] == table


NON_DEFAULT = {
    "none": {},
    "pic": {"delay_mode": "lead", "contact_force": 5.0, "forgetting": 0.9, "stiffness_walk": 0.0},
    "dac": {"alpha_max": 500.0, "damping_initial": 20.0, "noise_std": 0.3, "observer": "paper"},
    "pida": {"stiffness_initial": 2e5, "stiffness_std": 5e4, "damping_std": 100.0, "damping_walk": 0.0},
    "tdpa-impedance": {"alpha_max": 100.0, "velocity_floor": 5e-4},
    "tdpa-admittance": {"beta_max": 2e-5, "force_floor": 0.5, "contact_force": 1.0},
    "model-mediated": {"law": "linear", "match_angle": 20.0, "residual_gain": 0.5, "correct_priors": False},
}


@pytest.mark.parametrize("kind", KINDS)
def test_toml_round_trip_for_each_kind(kind, tmp_path):
    s = hc.load_scenario(PRESET, {"compensator": {"kind": kind, **NON_DEFAULT[kind]}})
    for key, value in NON_DEFAULT[kind].items():
        assert getattr(s.compensator, key) == value
    text = s.to_toml()
    assert tomllib.loads(text)["compensator"] == {"kind": kind, **DEFAULTS[kind], **NON_DEFAULT[kind]}
    again = hc.Scenario.from_toml(text)
    assert again == s and type(again.compensator) is type(s.compensator)
    assert again.to_toml() == text
    path = tmp_path / "resolved.toml"
    path.write_text(text, encoding="utf-8")
    assert hc.load_scenario(path) == s


def test_integers_are_accepted_for_compensator_numbers():
    s = hc.load_scenario(PRESET, {"compensator.kind": "pida", "compensator.alpha_max": 1500})
    assert s.compensator.alpha_max == 1500.0 and isinstance(s.compensator.alpha_max, float)


MODEL_RANGE_ERRORS = [
    ("contact_force", 0.0, "must be > 0 and <= 1e6, got 0.0"),
    ("stiffness_initial", -1.0, "must be > 0 and <= 1e11, got -1.0"),
    ("damping_initial", -0.5, "must be between 0 and 1e9, got -0.5"),
    ("stiffness_std", 0, "must be > 0 and <= 1e11, got 0"),
    ("damping_std", 0.0, "must be > 0 and <= 1e9, got 0.0"),
    ("stiffness_walk", -1.0, "must be between 0 and 1e11, got -1.0"),
    ("damping_walk", -0.1, "must be between 0 and 1e9, got -0.1"),
    ("noise_std", 0.0, "must be > 0 and <= 1e6, got 0.0"),
    ("forgetting", 1.5, "must be between 0 and 1 (exclusive), got 1.5"),
    ("forgetting", 1.0, "must be between 0 and 1 (exclusive), got 1.0"),
    ("forgetting", 0.0, "must be between 0 and 1 (exclusive), got 0.0"),
    ("forgetting", float("nan"), "must be a finite number, got nan"),
    ("alpha_max", -2000.0, "must be > 0 and <= 1e12, got -2000.0"),
    ("alpha_max", float("inf"), "must be a finite number, got inf"),
    ("alpha_max", "big", "expected a number, got 'big'"),
    ("delay_mode", "predict", "must be one of 'align' or 'lead', got 'predict'"),
    ("observer", "exact", "must be one of 'work' or 'paper', got 'exact'"),
]


@pytest.mark.parametrize("kind", ["pic", "dac", "pida"])
@pytest.mark.parametrize(("key", "value", "expected"), MODEL_RANGE_ERRORS)
def test_model_params_range_errors_name_the_key(kind, key, value, expected):
    message = error_of(PRESET, {"compensator.kind": kind, f"compensator.{key}": value})
    assert message == f"compensator.{key}: {expected}"


TDPA_RANGE_ERRORS = [
    ("contact_force", -3.0, "must be > 0 and <= 1e6, got -3.0"),
    ("alpha_max", 0.0, "must be > 0 and <= 1e12, got 0.0"),
    ("beta_max", 0.0, "must be > 0 and <= 1000, got 0.0"),
    ("velocity_floor", -1e-3, "must be > 0 and <= 1000, got -0.001"),
    ("force_floor", 0, "must be > 0 and <= 1e6, got 0"),
    ("beta_max", float("nan"), "must be a finite number, got nan"),
]


@pytest.mark.parametrize("kind", ["tdpa-impedance", "tdpa-admittance"])
@pytest.mark.parametrize(("key", "value", "expected"), TDPA_RANGE_ERRORS)
def test_tdpa_params_range_errors_name_the_key(kind, key, value, expected):
    message = error_of(PRESET, {"compensator.kind": kind, f"compensator.{key}": value})
    assert message == f"compensator.{key}: {expected}"


def test_range_limits_are_inclusive_where_documented():
    s = hc.load_scenario(
        PRESET,
        {"compensator.kind": "pic", "compensator.damping_initial": 0.0, "compensator.stiffness_walk": 0.0,
         "compensator.damping_walk": 0.0, "compensator.forgetting": 0.999999},
    )
    assert (s.compensator.damping_initial, s.compensator.stiffness_walk, s.compensator.damping_walk) == (0.0,) * 3


def test_unknown_kind_lists_the_allowed_kinds(scenario_file):
    message = error_of(PRESET, {"compensator.kind": "pid"})
    assert message == (
        "compensator.kind: unknown compensator kind 'pid'; allowed: 'none', 'pic', 'dac', 'pida', "
        "'tdpa-impedance', 'tdpa-admittance', 'model-mediated'"
    )
    text = tomllib.loads(hc.load_scenario(PRESET).to_toml())
    text["compensator"] = {"kind": "smith-predictor", "alpha_max": 1.0}
    assert error_of(text).startswith("compensator.kind: unknown compensator kind 'smith-predictor'; allowed: 'none'")


def test_unknown_compensator_key_lists_the_kinds_allowed_keys():
    message = error_of(PRESET, {"compensator.kind": "tdpa-impedance", "compensator.forgeting": 0.9})
    assert message.startswith(
        "compensator.forgeting: unknown key; allowed keys in [compensator] with kind = 'tdpa-impedance': "
        "kind, contact_force, alpha_max, beta_max, velocity_floor, force_floor"
    )
    assert "did you mean" not in message  # nothing close among the TDPA keys
    message = error_of(PRESET, {"compensator.kind": "pida", "compensator.forgeting": 0.9})
    assert "(did you mean 'forgetting'?)" in message
    # a parameter of another kind says which kinds have it
    message = error_of(PRESET, {"compensator.alpha_max": 10.0})  # the preset's kind is none
    assert message.startswith("compensator.alpha_max: unknown key; allowed keys in [compensator] with kind = 'none': kind")
    assert "'alpha_max' is a parameter of kind 'pic', 'dac', 'pida', 'tdpa-impedance', 'tdpa-admittance'" in message
    message = error_of(PRESET, {"compensator.kind": "pida", "compensator.beta_max": 1e-4})
    assert message.startswith("compensator.beta_max: unknown key")
    assert "kind 'tdpa-impedance', 'tdpa-admittance')" in message


@pytest.mark.parametrize("name", preset_names())
@pytest.mark.parametrize("kind", KINDS)
def test_switching_kind_by_override_works_on_every_preset(name, kind):
    assert "compensator" in raw_preset(name)
    s = hc.load_scenario(name, {"compensator.kind": kind})
    assert s.compensator.kind == kind
    # the defaults, with the file's own parameters that the new kind has (the others dropped)
    own = {k: v for k, v in raw_preset(name)["compensator"].items() if k in DEFAULTS[kind]}
    assert s.to_dict()["compensator"] == {"kind": kind, **DEFAULTS[kind], **own}
    base = hc.load_scenario(name).to_dict()
    switched = s.to_dict()
    assert {k: v for k, v in switched.items() if k != "compensator"} == {
        k: v for k, v in base.items() if k != "compensator"
    }
    again = hc.Scenario.from_toml(s.to_toml())
    assert again == s


def file_with_compensator(scenario_file, table: dict) -> str:
    raw = raw_preset()
    raw["compensator"] = table
    return scenario_file(tomli_w.dumps(raw))


def test_switching_kind_keeps_only_the_files_parameters_of_the_new_kind(scenario_file):
    path = file_with_compensator(
        scenario_file,
        {"kind": "tdpa-impedance", "alpha_max": 150.0, "beta_max": 3e-5, "velocity_floor": 2e-3},
    )
    assert hc.load_scenario(path).compensator.beta_max == 3e-5
    # to pida: beta_max and velocity_floor (tdpa only) are dropped, alpha_max (shared) is kept
    pida = hc.load_scenario(path, {"compensator.kind": "pida"}).compensator
    assert pida.kind == "pida" and pida.alpha_max == 150.0 and pida.forgetting == 0.98
    # to the other TDPA: everything is kept
    admittance = hc.load_scenario(path, {"compensator.kind": "tdpa-admittance"}).compensator
    assert (admittance.alpha_max, admittance.beta_max, admittance.velocity_floor) == (150.0, 3e-5, 2e-3)
    # to none: everything is dropped
    assert hc.load_scenario(path, {"compensator.kind": "none"}).to_dict()["compensator"] == {"kind": "none"}
    # the order of the overrides does not matter; explicit parameters win over the file's
    for overrides in (
        {"compensator.alpha_max": 99.0, "compensator.kind": "dac"},
        {"compensator.kind": "dac", "compensator.alpha_max": 99.0},
    ):
        dac = hc.load_scenario(path, overrides).compensator
        assert dac.kind == "dac" and dac.alpha_max == 99.0


def test_explicit_parameter_of_another_kind_is_an_error_after_a_switch(scenario_file):
    path = file_with_compensator(scenario_file, {"kind": "pic", "forgetting": 0.95})
    for overrides in (
        {"compensator.kind": "tdpa-admittance", "compensator.forgetting": 0.9},
        {"compensator.forgetting": 0.9, "compensator.kind": "tdpa-admittance"},
    ):
        message = error_of(path, overrides)
        assert message.startswith(
            "compensator.forgetting: unknown key; allowed keys in [compensator] with kind = 'tdpa-admittance'"
        )


def test_same_kind_override_keeps_the_files_mistakes(scenario_file):
    # not a switch: a wrong key in the file is still reported
    path = file_with_compensator(scenario_file, {"kind": "pida", "alpha_maxx": 1.0})
    message = error_of(path, {"compensator.kind": "pida"})
    assert message.startswith("compensator.alpha_maxx: unknown key (did you mean 'alpha_max'?)")
    assert error_of(path).startswith("compensator.alpha_maxx: unknown key")


def test_switch_to_unknown_kind_is_reported_not_dropped(scenario_file):
    path = file_with_compensator(scenario_file, {"kind": "pic", "forgetting": 0.95})
    assert error_of(path, {"compensator.kind": "pdia"}).startswith("compensator.kind: unknown compensator kind 'pdia'")


def test_kind_switch_in_apply_overrides_does_not_mutate_the_input():
    raw = raw_preset()
    raw["compensator"] = {"kind": "pic", "forgetting": 0.95}
    out = apply_overrides(raw, {"compensator.kind": "tdpa-impedance"})
    assert out["compensator"] == {"kind": "tdpa-impedance"}
    assert raw["compensator"] == {"kind": "pic", "forgetting": 0.95}


def test_public_api_has_compare():
    for name in ("compare", "Comparison"):
        assert name in hc.__all__ and hasattr(hc, name)


def test_model_mediated_prior_walls_are_checked_and_normalised():
    walls = [{"name": "cad-front", "point": [0.0101, 0.0, 0.0], "normal": [-2.0, 0.0, 0.0]}]
    s = hc.load_scenario(PRESET, {"compensator": {"kind": "model-mediated", "prior_walls": walls}})
    assert s.compensator.prior_walls[0].normal == [-1.0, 0.0, 0.0]
    zero = [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 0.0]}]
    message = error_of(PRESET, {"compensator": {"kind": "model-mediated", "prior_walls": zero}})
    assert "compensator.prior_walls[0].normal" in message and "nonzero" in message
    nine = [{"point": [0.0, 0.0, 0.0], "normal": [1.0, 0.0, 0.0]}] * 9
    assert "prior_walls" in error_of(PRESET, {"compensator": {"kind": "model-mediated", "prior_walls": nine}})
