"""`hilcontact identify` on a lab's own logs: plausibility checks that refuse a flipped force,
positions in mm, a time in ms, a velocity in the wrong unit or sign (exit 2, one line naming
the cause and the --columns fix), the --columns mapping that fixes them, velocities and
moments optional, the project's own MCAP recordings and ROS 2 bags in MCAP, and the figures."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

import hilcontact as hc
from hilcontact.cli import cli
from hilcontact.recording import IDENTIFY_COLUMNS, RecordingError, parse_columns

K_TRUE = 176275.0  # N/m, paper-table1


def invoke(*args: object):
    return CliRunner().invoke(cli, [str(a) for a in args], prog_name="hilcontact")


def assert_refused(result, out: Path, *fragments: str) -> str:
    assert result.exit_code == 2, (result.exit_code, result.output)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    for fragment in fragments:
        assert fragment in lines[0], lines[0]
    assert not out.exists()
    return lines[0]


def stiffnesses(out: Path) -> np.ndarray:
    return pd.read_csv(out / "collisions.csv")["stiffness"].to_numpy()


@pytest.fixture(scope="module")
def lab(core, tmp_path_factory) -> tuple[Path, pd.DataFrame]:
    """paper-table1 with pida at 20 ms: its scenario file and its identification columns."""
    folder = tmp_path_factory.mktemp("lab")
    sc = hc.load_scenario("paper-table1", {"compensator.kind": "pida", "facility.robot_delay": 0.02})
    run = hc.simulate(sc)
    (folder / "scenario.toml").write_text(run.scenario.to_toml())
    return folder / "scenario.toml", run.timeseries[IDENTIFY_COLUMNS].copy()


def test_a_correct_log_is_identified_without_a_warning(lab, tmp_path):
    scenario, data = lab
    data.to_csv(tmp_path / "log.csv", index=False)
    out = tmp_path / "id"
    result = invoke("identify", tmp_path / "log.csv", "--scenario", scenario, "--out", out)
    assert result.exit_code == 0, result.output
    assert "warning" not in result.stderr, result.stderr
    k = stiffnesses(out)
    assert len(k) >= 4 and np.all(np.abs(k / K_TRUE - 1) < 0.01), k


def test_a_flipped_force_is_refused_and_columns_fixes_it(lab, tmp_path):
    scenario, data = lab
    flipped = data.copy()
    for a in "xyz":
        flipped[f"measured_force_{a}"] *= -1
    log = tmp_path / "log.csv"
    flipped.to_csv(log, index=False)
    out = tmp_path / "id"
    line = assert_refused(invoke("identify", log, "--scenario", scenario, "--out", out), out,
                          "force and penetration are anticorrelated", "is the force's sign flipped?",
                          "--columns fx=-measured_force_x")
    assert "k = -" in line  # the identification it refused
    fixed = ",".join(f"f{a}=-measured_force_{a}" for a in "xyz")
    result = invoke("identify", log, "--scenario", scenario, "--columns", fixed, "--out", out)
    assert result.exit_code == 0, result.output
    assert np.all(np.abs(stiffnesses(out) / K_TRUE - 1) < 0.01)
    # --unchecked writes it anyway, with the finding as a warning
    result = invoke("identify", log, "--scenario", scenario, "--unchecked", "--out", tmp_path / "raw")
    assert result.exit_code == 0 and "warning: force and penetration are anticorrelated" in result.stderr
    assert np.all(stiffnesses(tmp_path / "raw") < 0)


def test_positions_in_mm_are_refused_and_columns_fixes_them(lab, tmp_path):
    scenario, data = lab
    mm = data.copy()
    for a in "xyz":
        # a lab frame whose origin is 10 m away, in mm
        mm[f"actual_tip_position_{a}"] = mm[f"actual_tip_position_{a}"] * 1e3 + 1e4
        mm[f"actual_tip_velocity_{a}"] *= 1e3
    log = tmp_path / "log.parquet"
    mm.to_parquet(log, index=False)
    out = tmp_path / "id"
    assert_refused(invoke("identify", log, "--scenario", scenario, "--out", out), out,
                   "implausibly low", "are the positions in mm?", "px=actual_tip_position_x:mm",
                   "vx=actual_tip_velocity_x:mm/s")
    fixed = ",".join(f"p{a}=actual_tip_position_{a}:mm,v{a}=actual_tip_velocity_{a}:mm/s" for a in "xyz")
    result = invoke("identify", log, "--scenario", scenario, "--columns", fixed, "--out", out)
    assert result.exit_code == 0, result.output
    assert np.all(np.abs(stiffnesses(out) / K_TRUE - 1) < 0.01)


def test_positions_in_mm_with_the_velocity_in_m_per_s_are_refused(lab, tmp_path):
    scenario, data = lab
    mixed = data.copy()
    for a in "xyz":
        mixed[f"actual_tip_position_{a}"] *= 1e3
    log = tmp_path / "log.csv"
    mixed.to_csv(log, index=False)
    out = tmp_path / "id"
    assert_refused(invoke("identify", log, "--scenario", scenario, "--out", out), out,
                   "the velocity is 0.001 times the position's derivative")


def test_a_flipped_velocity_is_refused(lab, tmp_path):
    scenario, data = lab
    flipped = data.copy()
    flipped["actual_tip_velocity_x"] *= -1
    log = tmp_path / "log.csv"
    flipped.to_csv(log, index=False)
    out = tmp_path / "id"
    assert_refused(invoke("identify", log, "--scenario", scenario, "--out", out), out,
                   "opposite signs", "--columns vx=-actual_tip_velocity_x")


def test_time_in_ms_is_refused(lab, tmp_path):
    scenario, data = lab
    ms = data.copy()
    ms["time"] *= 1e3
    log = tmp_path / "log.csv"
    ms.to_csv(log, index=False)
    out = tmp_path / "id"
    assert_refused(invoke("identify", log, "--scenario", scenario, "--out", out), out,
                   "time steps of 1 s", "is time in ms? (--columns t=time:ms)")
    result = invoke("identify", log, "--scenario", scenario, "--columns", "t=time:ms", "--out", out)
    assert result.exit_code == 0, result.output


@pytest.mark.parametrize("suffix", ["csv", "parquet"])
def test_a_labs_own_names_units_and_no_velocities(lab, tmp_path, suffix):
    """Columns named as a lab names them, force in kN with z flipped, positions in mm, time in
    ms, no velocity and no moment columns: mapped, differentiated, identified within 1 %."""
    scenario, data = lab
    own = pd.DataFrame({
        "stamp_ms": data["time"] * 1e3,
        "Fx_kN": data["measured_force_x"] / 1e3, "Fy_kN": data["measured_force_y"] / 1e3,
        "Fz": -data["measured_force_z"],
        "x_mm": data["actual_tip_position_x"] * 1e3, "y_mm": data["actual_tip_position_y"] * 1e3,
        "z_mm": data["actual_tip_position_z"] * 1e3,
    })
    log = tmp_path / f"log.{suffix}"
    own.to_csv(log, index=False) if suffix == "csv" else own.to_parquet(log, index=False)
    out = tmp_path / "id"
    columns = "t=stamp_ms:ms,fx=Fx_kN:kN,fy=Fy_kN:kN,fz=-Fz,px=x_mm:mm,py=y_mm:mm,pz=z_mm:mm"
    result = invoke("identify", log, "--scenario", scenario, "--columns", columns, "--out", out)
    assert result.exit_code == 0, result.output
    assert "actual_tip_velocity_*: differentiated from the position" in result.stderr
    assert "measured_moment_*: not in the recording, taken as zero" in result.stderr
    k = stiffnesses(out)
    assert len(k) >= 4 and np.all(np.abs(k / K_TRUE - 1) < 0.01), k
    derived = json.loads((out / "collisions.json").read_text())["derived"]
    assert len(derived) == 2


def test_a_missing_velocity_without_positions_is_still_named(lab, tmp_path):
    scenario, data = lab
    log = tmp_path / "log.csv"
    data.drop(columns=["actual_tip_position_y", "actual_tip_velocity_x", "actual_tip_velocity_y",
                       "actual_tip_velocity_z"]).to_csv(log, index=False)
    out = tmp_path / "id"
    assert_refused(invoke("identify", log, "--scenario", scenario, "--out", out), out,
                   "missing columns: actual_tip_position_y, actual_tip_velocity_x")


@pytest.mark.parametrize("spec, fragment", [
    ("fz", "expected KEY=[-]SOURCE[:UNIT]"),
    ("q=Fz", "unknown key 'q'"),
    ("px=x:furlong", "unit 'furlong' is not a position unit (m, cm, mm, um, in)"),
    ("fz=nothing", "no column 'nothing'"),
])
def test_bad_columns_are_refused_with_one_line(lab, tmp_path, spec, fragment):
    scenario, data = lab
    log = tmp_path / "log.csv"
    data.to_csv(log, index=False)
    out = tmp_path / "id"
    assert_refused(invoke("identify", log, "--scenario", scenario, "--columns", spec, "--out", out), out, fragment)


def test_parse_columns():
    assert parse_columns("fx=Fx_N, px=x_mm:mm,fz=-Fz,t=ts:us") == {
        "measured_force_x": ("Fx_N", 1.0, "N"), "actual_tip_position_x": ("x_mm", 1.0, "mm"),
        "measured_force_z": ("Fz", -1.0, "N"), "time": ("ts", 1.0, "us"),
    }
    with pytest.raises(RecordingError):
        parse_columns("vx=v:mm")  # a position unit for a velocity


# ---- MCAP ----------------------------------------------------------------------------------------


def test_identify_reads_the_projects_own_mcap(core, tmp_path):
    pytest.importorskip("mcap_ros2.decoder")
    sc = hc.load_scenario("paper-exp-2.64hz", {"compensator.kind": "pida"})
    path = tmp_path / "sim.mcap"
    run = hc.simulate(sc, mcap=str(path))
    run.save(tmp_path / "run", plots=False)
    out_mcap, out_run = tmp_path / "id-mcap", tmp_path / "id-run"
    # no --scenario: the file carries its own (sensor delay 5 ms, 0.2 N noise)
    result = invoke("identify", path, "--out", out_mcap)
    assert result.exit_code == 0, result.output
    assert invoke("identify", tmp_path / "run", "--out", out_run).exit_code == 0
    a, b = pd.read_csv(out_mcap / "collisions.csv"), pd.read_csv(out_run / "collisions.csv")
    # the same samples (the MCAP holds the time series' values): the same identification
    assert len(a) == len(b) >= 4
    np.testing.assert_allclose(a["stiffness"], b["stiffness"], rtol=1e-9)
    np.testing.assert_allclose(a["damping"], b["damping"], rtol=1e-6, atol=1e-6)
    assert np.all(np.abs(a["stiffness"] / sc.contact.stiffness - 1) < 0.02)
    assert (out_mcap / "identification.png").exists() and (out_mcap / "force_penetration.png").exists()


def write_ros2_mcap_bag(path: Path, data: pd.DataFrame) -> None:
    """A ROS 2 bag with MCAP storage (rosbags), WrenchStamped /ft and PoseStamped /tip."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    Header, Time = T["std_msgs/msg/Header"], T["builtin_interfaces/msg/Time"]
    Vector3, Point, Quaternion = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Point"], T["geometry_msgs/msg/Quaternion"]
    Wrench, WrenchStamped = T["geometry_msgs/msg/Wrench"], T["geometry_msgs/msg/WrenchStamped"]
    Pose, PoseStamped = T["geometry_msgs/msg/Pose"], T["geometry_msgs/msg/PoseStamped"]
    with Writer(path, version=8, storage_plugin=StoragePlugin.MCAP) as writer:
        cw = writer.add_connection("/ft", WrenchStamped.__msgtype__, typestore=ts)
        cp = writer.add_connection("/tip", PoseStamped.__msgtype__, typestore=ts)
        t0 = 1_700_000_000 * 10**9
        for row in data.itertuples(index=False):
            ns = t0 + int(round(row.time * 1e9))
            header = Header(stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id="t")
            wrench = WrenchStamped(header=header, wrench=Wrench(
                force=Vector3(x=row.measured_force_x, y=row.measured_force_y, z=row.measured_force_z),
                torque=Vector3(x=row.measured_moment_x, y=row.measured_moment_y, z=row.measured_moment_z)))
            writer.write(cw, ns, ts.serialize_cdr(wrench, WrenchStamped.__msgtype__))
            pose = PoseStamped(header=header, pose=Pose(
                position=Point(x=row.actual_tip_position_x, y=row.actual_tip_position_y, z=row.actual_tip_position_z),
                orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)))
            writer.write(cp, ns, ts.serialize_cdr(pose, PoseStamped.__msgtype__))


def test_identify_reads_a_ros2_bag_in_mcap(lab, tmp_path):
    pytest.importorskip("rosbags")
    pytest.importorskip("mcap_ros2.decoder")
    scenario, data = lab
    bag = tmp_path / "bag"
    write_ros2_mcap_bag(bag, data)
    files = sorted(bag.glob("*.mcap"))
    assert len(files) == 1
    # the bag folder (rosbags) and its .mcap file alone (mcap): velocities differentiated
    for source in (bag, files[0]):
        out = tmp_path / f"id-{source.name}"
        result = invoke("identify", source, "--scenario", scenario, "--out", out)
        assert result.exit_code == 0, result.output
        k = stiffnesses(out)
        assert len(k) >= 4 and np.all(np.abs(k / K_TRUE - 1) < 0.01), (source, k)


def test_an_mcap_without_a_wrench_topic_is_refused(lab, tmp_path):
    pytest.importorskip("rosbags")
    pytest.importorskip("mcap_ros2.decoder")
    scenario, data = lab
    bag = tmp_path / "bag"
    write_ros2_mcap_bag(bag, data.iloc[:50])
    mcap = next(bag.glob("*.mcap"))
    out = tmp_path / "id"
    assert_refused(invoke("identify", mcap, "--scenario", scenario, "--wrench-topic", "/nothing", "--out", out), out,
                   "no topic /nothing (--wrench-topic)", "/ft")


# ---- real time: stale sensor records ----------------------------------------------------------


def test_held_sensor_records_are_identified_with_the_kinematics_that_produced_them(lab, tmp_path):
    """A real-time run's ticks without a new sensor record reuse the last force while the
    kinematics move on (`sensor_age` > 0). Emulated here on a simulated run: a third of the
    ticks hold the previous record. Paired with the present kinematics (the loop's own
    identification, and `identify` before) k came out several per cent low and c negative;
    paired with the kinematics of the tick the record arrived at, within 1 %."""
    scenario, data = lab
    rng = np.random.default_rng(5)
    stale = rng.random(len(data)) < 1 / 3
    stale[0] = False
    held = data.copy()
    source = np.maximum.accumulate(np.where(stale, 0, np.arange(len(data))))
    for name in [c for c in IDENTIFY_COLUMNS if c.startswith("measured_")]:
        held[name] = data[name].to_numpy()[source]
    age = (np.arange(len(data)) - source) * 1e-3
    log_without, log_with = tmp_path / "without.parquet", tmp_path / "with.parquet"
    held.to_parquet(log_without, index=False)
    held.assign(sensor_age=age).to_parquet(log_with, index=False)
    errors = {}
    for name, log in (("without", log_without), ("with", log_with)):
        out = tmp_path / name
        result = invoke("identify", log, "--scenario", scenario, "--unchecked", "--out", out)
        assert result.exit_code == 0, result.output
        errors[name] = np.abs(stiffnesses(out) / K_TRUE - 1)
    assert np.max(errors["with"]) < 0.01, errors
    assert np.median(errors["without"]) > 3 * np.max(errors["with"]), errors
