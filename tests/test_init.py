"""`hilcontact init`: a commented scenario file that loads back to the scenario it came from."""

from __future__ import annotations

import os
import subprocess
import sys
import tomllib

import pytest
from click.testing import CliRunner

import hilcontact as hc
from hilcontact.cli import cli
from hilcontact.scenario import COMPENSATOR_MODELS, _TABLES
from hilcontact.template import commented_toml


def invoke(*args: str):
    return CliRunner().invoke(cli, list(args), prog_name="hilcontact")


@pytest.mark.parametrize("preset", hc.presets())
@pytest.mark.parametrize("kind", list(COMPENSATOR_MODELS))
def test_every_key_is_commented_and_the_file_loads_back(preset, kind):
    scenario = hc.load_scenario(preset, {"compensator.kind": kind})
    text = commented_toml(scenario)
    assert hc.load_scenario(tomllib.loads(text)) == scenario
    lines = text.splitlines()
    keys = [i for i, line in enumerate(lines) if " = " in line and not line.startswith(("#", " ", "["))]
    assert keys
    for i in keys:  # every key has its comment right above it, with a default or "required"
        assert lines[i - 1].startswith("# ") and "[" in "".join(lines[max(i - 4, 0):i]), lines[i - 4:i + 1]
    commented = "\n".join(line for line in lines if line.startswith("#"))
    for table, model in _TABLES.items():
        if isinstance(model, dict):
            model = model[kind]
        for name, field in model.model_fields.items():
            if f"\n{name} = " in text or text.startswith(f"{name} = "):
                first_words = " ".join((field.description or "").split()[:3])
                assert first_words in commented.replace("\n# ", " "), (table, name)
    assert "# Stiffness k: N/m (linear)" in text and "[required]" in text and "[default 0.0]" in text


def test_cli_init_writes_runnable_file_and_keeps_an_existing_one(core, tmp_path):
    target = tmp_path / "my.toml"
    result = invoke("init", str(target), "--from", "paper-table1", "--set", "simulation.duration=0.5")
    assert result.exit_code == 0, (result.output, result.stderr)
    assert f"wrote {target}" in result.stdout
    assert hc.load_scenario(target).simulation.duration == 0.5
    target.write_text("# mine\n")
    renamed = invoke("init", str(tmp_path / "lab.toml"), "--from", "paper-exp-1.93hz", "--set", "name=lab")
    assert renamed.exit_code == 0 and "(from paper-exp-1.93hz)" in renamed.stdout, renamed.output  # not "from lab"
    assert hc.load_scenario(tmp_path / "lab.toml").name == "lab"
    again = invoke("init", str(target))
    assert again.exit_code == 2 and "exists" in again.stderr and len(again.stderr.strip().splitlines()) == 1
    assert target.read_text() == "# mine\n"
    assert invoke("init", str(target), "--force").exit_code == 0
    assert hc.load_scenario(target) == hc.load_scenario("paper-table1")
    # the README's example then works as written
    run = subprocess.run([sys.executable, "-m", "hilcontact", "run", str(target), "--no-plots",
                          "--set", "simulation.duration=0.5", "--out", str(tmp_path / "out")],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".my")) == []  # no temporary file


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["init", "DIR"], "is a folder"),
        (["init", "x.txt"], "ends in .toml"),
        (["init", "x.toml", "--from", "nope"], "unknown scenario 'nope'"),
        (["init", "x.toml", "--set", "contact.stiffness=-1"], "contact.stiffness"),
    ],
)
def test_cli_init_refuses_bad_input_in_one_line(tmp_path, args, fragment):
    (tmp_path / "DIR").mkdir()
    old = os.getcwd()
    os.chdir(tmp_path)
    try:
        result = invoke(*args)
    finally:
        os.chdir(old)
    assert result.exit_code == 2, (result.output, result.stderr)
    assert fragment in result.stderr and len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["DIR"]
