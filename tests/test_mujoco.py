"""MuJoCo as an independent engine (docs/mujoco.md): the MJCF writer, the cross-check of the ideal
reference against MuJoCo (issue 21's targets: rebound velocity vectors within 2 %, impulses
within 3 % where the models are matched) and the facility engine ``facility.kind = "mujoco"``."""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest

import hilcontact as hc
from hilcontact.errors import ArgumentError, ScenarioError

from test_cli import assert_one_error_line, invoke

mujoco = pytest.importorskip("mujoco")

from hilcontact.mujoco import crosscheck as cc  # noqa: E402
from hilcontact.mujoco.mjcf import ContactMatch, inertia_matrix, write_mjcf  # noqa: E402

#: Issue 21's targets for matched models.
VELOCITY_TOLERANCE = 0.02
IMPULSE_TOLERANCE = 0.03


def _case(name: str) -> cc.Case:
    return next(c for c in cc.CASES if c.name == name)


def test_mjcf_holds_the_scenario_bodies_and_the_matched_law(core):
    """The written model has the scenario's masses, inertia tensors (products included), poses;
    its contact's solref is (−k·(1−d)·A, −c·(1−d)·A) with A = 1/m_s + 1/m_t, MuJoCo's
    approximate inverse inertia of a contact between two free bodies (docs/mujoco.md)."""
    s = hc.load_scenario("oblique-6dof", {"contact.damping": 120.0})
    xml, matched = write_mjcf(s, 1e-4)
    m = mujoco.MjModel.from_xml_string(xml)
    for name, body in (("servicer", s.servicer), ("target", s.target)):
        b = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name)
        assert m.body_mass[b] == pytest.approx(body.mass, rel=1e-12)
        # MuJoCo diagonalises the tensor: its principal moments are the tensor's eigenvalues
        assert np.sort(m.body_inertia[b]) == pytest.approx(np.linalg.eigvalsh(inertia_matrix(body.inertia)), rel=1e-9)
        assert m.body_pos[b] == pytest.approx(body.position)
    assert matched.diag == pytest.approx(1 / s.servicer.mass + 1 / s.target.mass, rel=1e-9)
    d = ContactMatch().impedance
    assert matched.solref[0] == pytest.approx(-s.contact.stiffness * (1 - d) * matched.diag, rel=1e-12)
    assert matched.solref[1] == pytest.approx(-120.0 * (1 - d) * matched.diag, rel=1e-12)
    assert m.npair == len(s.walls)


def test_mjcf_refuses_hunt_crossley(core):
    s = hc.load_scenario("oblique-6dof", {"contact.model": "hunt-crossley"})
    with pytest.raises(ScenarioError, match="contact.model"):
        write_mjcf(s, 1e-4)


def _check(rows, velocity=VELOCITY_TOLERANCE, impulse=IMPULSE_TOLERANCE, episodes=1):
    assert len(rows) >= episodes
    for row in rows[:episodes]:
        assert row["velocity_error"] <= velocity, row
        assert row["normal_impulse_error"] <= impulse, row
        assert row["tangential_impulse_error"] <= impulse, row
        assert row["angular_impulse_error"] <= impulse, row


def test_crosscheck_frictionless_oblique_6dof(core):
    """Tilted wall, offset tip, both bodies turning: the matched linear law agrees far inside the
    targets (the rest is MuJoCo's Euler step and its O(d) coupling)."""
    rows = cc.run_case(_case("oblique frictionless"))
    _check(rows, velocity=1e-3, impulse=1e-3)
    assert rows[0]["angular_velocity_error"] <= 1e-3
    assert rows[0]["walls"] == [0]


def test_crosscheck_sliding_friction(core):
    """μ = 0.1: the tip slides through the whole contact; MuJoCo's cone and the regularised
    Coulomb law agree."""
    rows = cc.run_case(_case("oblique mu=0.1"))
    _check(rows)
    # sliding all along: |J_t| is nearly μ·J_n (a little less: the law's regularisation)
    assert 0.09 * rows[0]["normal_impulse"][0] < rows[0]["tangential_impulse"] <= 0.1 * rows[0]["normal_impulse"][0]


def test_crosscheck_corner_two_walls_at_once(core):
    """The tip in a corner: both walls push at once (one episode, two walls), each one's normal
    impulse matched."""
    rows = cc.run_case(_case("corner frictionless"))
    _check(rows, velocity=1e-3, impulse=1e-3)
    assert rows[0]["walls"] == [0, 1]
    assert min(rows[0]["normal_impulse"]) > 0.2 * max(rows[0]["normal_impulse"])


def test_crosscheck_regularisation_is_what_differs(core):
    """μ = 0.3 slides at a few v_ε, where the regularised law's friction is below μ·F_n
    (μ·s/√(s² + v_ε²)). MuJoCo's viscous friction up to the cone (its own regularisation, the
    slope following F_n only) gives μ·F_n there: the rebound differs by more than the target.
    With the slope following the sliding speed too (the law's secant, the default) the models are
    matched, at the default v_ε and at a ten times narrower one."""
    own = cc.run_case(_case("oblique mu=0.3"), match=ContactMatch(track_sliding=False))
    assert own[0]["velocity_error"] > VELOCITY_TOLERANCE
    _check(cc.run_case(_case("oblique mu=0.3")))
    _check(cc.run_case(_case("oblique mu=0.3 v_eps=0.1mm/s")))


def _collisions(run):
    return [(c["cov"], c["cof"]) for c in run.metrics["collisions"]]


@pytest.mark.parametrize("preset", ["paper-table1", "oblique-6dof"])
def test_mujoco_facility_reproduces_the_model_facility_at_zero_delay(core, preset):
    """Zero delay, no compensator: the HIL loop on MuJoCo's contact gives the CoV and CoF of the
    model facility within the cross-check's tolerances, collision by collision."""
    model = hc.simulate(hc.load_scenario(preset, {"facility.robot_delay": 0.0}))
    mj = hc.simulate(hc.load_scenario(preset, {"facility.robot_delay": 0.0, "facility.kind": "mujoco"}))
    assert mj.status == "ok" and model.status == "ok"
    a, b = _collisions(model), _collisions(mj)
    assert len(a) == len(b) >= 2
    for (cov_m, cof_m), (cov_j, cof_j) in zip(a, b):
        assert abs(cov_j - cov_m) <= VELOCITY_TOLERANCE
        assert abs(cof_j - cof_m) <= IMPULSE_TOLERANCE
    # the mujoco facility's contact force is MuJoCo's, not the model's: not bit-identical
    assert not np.array_equal(model.timeseries["contact_force_x"], mj.timeseries["contact_force_x"])


@pytest.mark.parametrize("preset", ["paper-table1", "oblique-6dof"])
def test_pida_stays_faithful_on_the_mujoco_facility(core, preset):
    """20 ms robot delay: pida is faithful on the MuJoCo facility as on the model one, with the
    same CoV and CoF within the tolerances; without a compensator neither is."""
    over = {"facility.robot_delay": 0.02, "compensator.kind": "pida"}
    model = hc.simulate(hc.load_scenario(preset, over))
    mj = hc.simulate(hc.load_scenario(preset, {**over, "facility.kind": "mujoco"}))
    assert model.status == mj.status == "ok"
    for (cov_m, cof_m), (cov_j, cof_j) in zip(_collisions(model), _collisions(mj)):
        assert abs(cov_j - cov_m) <= VELOCITY_TOLERANCE
        assert abs(cof_j - cof_m) <= IMPULSE_TOLERANCE
    bare = hc.simulate(hc.load_scenario(preset, {"facility.robot_delay": 0.02, "facility.kind": "mujoco"}))
    assert bare.status != "ok"


def test_mujoco_model_file_beside_the_scenario(core, tmp_path):
    """facility.mujoco_model names an MJCF file relative to the scenario file; the model written
    from the scenario, saved there, gives the same run as writing it on the fly."""
    s = hc.load_scenario("paper-table1", {"facility.kind": "mujoco", "simulation.duration": 2.0})
    xml, _ = write_mjcf(s, 1e-4, fixed_target=True)
    (tmp_path / "hw").mkdir()
    (tmp_path / "hw" / "frame.xml").write_text(xml)
    data = s.to_dict()
    data["facility"]["mujoco_model"] = "hw/frame.xml"
    import tomli_w

    (tmp_path / "s.toml").write_text(tomli_w.dumps(data))
    from_file = hc.simulate(hc.load_scenario(str(tmp_path / "s.toml")))
    written = hc.simulate(s)
    assert from_file.scenario.facility.mujoco_model == str(tmp_path / "hw" / "frame.xml")
    assert _collisions(from_file) == _collisions(written)


def test_mujoco_model_file_missing_is_one_line(core, tmp_path):
    result = invoke("run", "paper-table1", "--set", "facility.kind=mujoco",
                    "--set", "facility.mujoco_model=nope.xml", "--out", "o", cwd=tmp_path)
    assert_one_error_line(result, "facility.mujoco_model", "nope.xml")
    assert list(tmp_path.iterdir()) == []


def test_core_refuses_to_build_the_mujoco_facility(core):
    """The core cannot build a Python engine: simulate (and the batch of a sweep) refuse it with
    a ScenarioError naming facility.kind, before running anything."""
    s = hc.load_scenario("paper-table1", {"facility.kind": "mujoco"})
    with pytest.raises(ScenarioError, match="facility.kind"):
        core.simulate(s.to_json())
    with pytest.raises(ScenarioError, match="facility.kind"):
        core.simulate_batch([s.to_json()])


def test_missing_mujoco_is_one_line_exit_2(core, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "mujoco", None)  # import mujoco raises ImportError
    with pytest.raises(ArgumentError, match=r"pip install 'hilcontact\[mujoco\]'"):
        hc.simulate(hc.load_scenario("paper-table1", {"facility.kind": "mujoco"}))
    result = invoke("run", "paper-table1", "--set", "facility.kind=mujoco", "--out", "o", cwd=tmp_path)
    assert_one_error_line(result, "mujoco", "pip install")
    assert list(tmp_path.iterdir()) == []


def test_run_folder_of_a_mujoco_run_reloads(core, tmp_path):
    """A run on the MuJoCo facility saves and reloads like any run (scenario.toml keeps the kind)."""
    s = hc.load_scenario("paper-table1", {"facility.kind": "mujoco", "simulation.duration": 1.0})
    run = hc.simulate(s)
    run.save(tmp_path / "r", plots=False)
    back = hc.Run.load(tmp_path / "r")
    assert back.scenario.facility.kind == "mujoco"
    assert json.loads((tmp_path / "r" / "metrics.json").read_text())["status"] == run.status


class _LawInPython:
    """The scenario's frictionless linear law at the rod tip, written in Python: a contact engine
    for ``_core.simulate_facility`` that must give the model facility's run (the adapter adds
    nothing of its own)."""

    def __init__(self, scenario, fail_at=None, bad_length=False):
        self.s = scenario
        self.calls = 0
        self.fail_at = fail_at
        self.bad_length = bad_length

    def contact_flat(self, motion):
        from hilcontact.mujoco.mjcf import rotation_matrix

        self.calls += 1
        if self.fail_at is not None and self.calls >= self.fail_at:
            raise RuntimeError("engine broke")
        if self.bad_length:
            return [0.0] * 8
        p, q, v, w = (np.asarray(motion[a:b]) for a, b in ((0, 3), (3, 7), (7, 10), (10, 13)))
        arm = rotation_matrix(q) @ np.asarray(self.s.rod.tip)
        tip, tip_v = p + arm, v + np.cross(w, arm)
        k, c = self.s.contact.stiffness, self.s.contact.damping
        force = np.zeros(3)
        for wall in self.s.walls:
            n = np.asarray(wall.normal) / np.linalg.norm(wall.normal)
            d = -(tip - np.asarray(wall.point)) @ n
            if d > 0:
                force += max(0.0, k * d + c * (-tip_v @ n)) * n
        moment = np.cross(tip - np.asarray(self.s.facility.sensor_position), -force)
        return [*force, *(-force), *moment, 0.0, 0.0, 0.0]


@pytest.mark.parametrize("preset", ["paper-table1", "oblique-6dof"])
def test_python_engine_with_the_models_law_reproduces_the_model_facility(core, preset):
    """The adapter (crates/py/src/facility.rs) with the model's own law in Python: the same run as
    the model facility (robot delay, sensor delay and noise included), to rounding."""
    over = {"facility.robot_delay": 0.01, "facility.sensor_delay": 0.002, "facility.sensor_noise": 0.5,
            "compensator.kind": "pida", "simulation.duration": 2.0}
    s = hc.load_scenario(preset, over)
    model = hc.simulate(s)
    result = core.simulate_facility(s.to_json(), _LawInPython(s))
    ours = json.loads(result["metrics"])
    for column in ("measured_force_x", "measured_moment_y", "actual_tip_position_x", "tip_velocity_x"):
        assert np.asarray(result["timeseries"][column]) == pytest.approx(model.timeseries[column].to_numpy(), rel=1e-9, abs=1e-9)
    assert ours["status"] == model.metrics["status"]
    assert [c["cov"] for c in ours["collisions"]] == pytest.approx([c["cov"] for c in model.metrics["collisions"]], rel=1e-9)


def test_python_engine_errors_stop_the_run_and_are_raised(core):
    s = hc.load_scenario("paper-table1", {"simulation.duration": 1.0})
    with pytest.raises(RuntimeError, match="engine broke"):
        core.simulate_facility(s.to_json(), _LawInPython(s, fail_at=50))
    with pytest.raises(ValueError, match="expected 12 numbers, got 8"):
        core.simulate_facility(s.to_json(), _LawInPython(s, bad_length=True))


def test_sweep_refuses_the_mujoco_facility_before_writing(core, tmp_path):
    result = invoke("sweep", "paper-table1", "--grid", "facility.robot_delay=0.01,0.02", "--compensators", "none",
                    "--set", "facility.kind=mujoco", "--out", "sw", cwd=tmp_path)
    assert_one_error_line(result, "facility.kind", "sweep")
    assert list(tmp_path.iterdir()) == []


def _random_scene(rng):
    """oblique-6dof with a random wall tilt, masses, stiffness and damping (up to 30 % of
    critical), the wall a few mm ahead of the tip along its normal."""
    s = hc.load_scenario("oblique-6dof")
    tip = np.array([0.005, 0.10, 0.05])  # the rod tip's start in t (the preset's)
    yaw, pitch = rng.uniform(-0.7, 0.7), rng.uniform(-0.5, 0.5)
    n = -np.array([np.cos(pitch) * np.cos(yaw), np.cos(pitch) * np.sin(yaw), np.sin(pitch)])
    m_s, m_t = rng.uniform(50, 2000), rng.uniform(500, 10000)
    k = 10 ** rng.uniform(4, 6)
    mu = m_s * m_t / (m_s + m_t)
    c = rng.uniform(0, 0.3) * 2 * np.sqrt(k * mu)
    speed = rng.uniform(0.01, 0.05)
    gap = 0.004
    approach = gap / (speed * -n[0])
    duration = approach + 3 * np.pi * np.sqrt(mu / k) + 0.05
    return hc.load_scenario(s, {
        "walls": [{"name": "w", "point": (tip - gap * n).tolist(), "normal": n.tolist()}],
        "servicer.mass": m_s, "target.mass": m_t, "servicer.velocity": [speed, 0.0, 0.0],
        "contact.stiffness": k, "contact.damping": c, "simulation.duration": float(duration),
        "facility.robot_delay": 0.0,
    })


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_crosscheck_random_frictionless_scenes(core, seed):
    """Random tilts, masses, stiffness and damping (seeded): the matched law agrees within the
    targets on every one (the damping's b' is matched too)."""
    s = _random_scene(np.random.default_rng(seed))
    rows = cc.crosscheck(s)
    _check(rows)
    assert rows[0]["walls"] == [0]


def test_mujoco_facility_with_sliding_friction(core):
    """μ = 0.1 at zero delay: MuJoCo's friction in the facility (its slope following the normal
    force at the robot's pose) gives the model facility's CoV and CoF within the tolerances."""
    over = {"facility.robot_delay": 0.0, "contact.friction.kinetic": 0.1}
    model = hc.simulate(hc.load_scenario("oblique-6dof", over))
    mj = hc.simulate(hc.load_scenario("oblique-6dof", {**over, "facility.kind": "mujoco"}))
    assert model.status == mj.status == "ok"
    for (cov_m, cof_m), (cov_j, cof_j) in zip(_collisions(model), _collisions(mj)):
        assert abs(cov_j - cov_m) <= VELOCITY_TOLERANCE
        assert abs(cof_j - cof_m) <= IMPULSE_TOLERANCE


# --- shapes in MJCF (docs/mujoco.md, "Shapes in MJCF") ------------------------------------------


def _shape_scene(target_shapes, servicer_shapes=None, **over):
    base = {"servicer.shapes": servicer_shapes or [{"name": "ball", "kind": "sphere", "radius": 0.02,
                                                     "position": [1.0, 0.0, 0.0]}],
            "target.shapes": target_shapes, "facility.robot_delay": 0.0, "simulation.duration": 0.8}
    base.update(over)
    return hc.load_scenario("rod-in-frame", base)


def _geom_surface_points(m, d, geom):
    """A mesh geom's vertices in the world (the target body's frame at rest), m."""
    mid = m.geom_dataid[geom]
    a, n = m.mesh_vertadr[mid], m.mesh_vertnum[mid]
    return m.mesh_vert[a:a + n] @ d.geom_xmat[geom].reshape(3, 3).T + d.geom_xpos[geom]


def test_mjcf_writes_every_shape_kind(core):
    """Box, cylinder, cone (rounded or sharp), sphere, capsule, half-space and mesh all become
    geoms; a rounded box's hull lies on the core dilated by the margin (outer size kept), a
    cone's hull spans base to apex, a mesh's flat convex pieces become one prism each whose front
    face is the piece."""
    from hilcontact.mujoco.mjcf import rotation_matrix

    size, margin = [0.04, 0.12, 0.02], 0.002
    cone = {"name": "cone", "kind": "cone", "radius": 0.03, "length": 0.05, "margin": 0.001,
            "position": [0.2, 0.3, 0.0], "orientation": [0.9, 0.1, 0.3, 0.2]}
    tri = {"name": "tri", "kind": "mesh", "vertices": [[0.3, 0, 0], [0.3, 0.1, 0], [0.3, 0, 0.1], [0.3, 0.1, 0.1]],
           "triangles": [[0, 1, 2], [1, 3, 2]]}
    s = _shape_scene([
        {"name": "bar", "kind": "box", "size": size, "margin": margin, "position": [0.04, 0.0, 0.0]},
        cone, tri,
        {"name": "ground", "kind": "half-space", "position": [0.0, 0.0, -0.5], "normal": [0.0, 0.0, 1.0]},
    ], servicer_shapes=[{"name": "rod", "kind": "cylinder", "radius": 0.01, "length": 0.3, "margin": 0.002,
                         "position": [1.0, 0.0, 0.0]},
                        {"name": "probe", "kind": "capsule", "radius": 0.01, "length": 0.1, "position": [1.0, 0.0, 0.5]}])
    xml, _ = write_mjcf(s, 1e-4)
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    g = {mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, i): i for i in range(m.ngeom)}
    assert m.geom_type[g["target-shape0-bar"]] == mujoco.mjtGeom.mjGEOM_MESH
    assert m.geom_type[g["servicer-shape1-probe"]] == mujoco.mjtGeom.mjGEOM_CAPSULE
    assert m.geom_type[g["target-shape3-ground"]] == mujoco.mjtGeom.mjGEOM_BOX  # the target floats
    # the rounded bar: outer size kept; every point on the core dilated by the margin
    p = _geom_surface_points(m, d, g["target-shape0-bar"]) - np.array([0.04, 0.0, 0.0])
    assert p.max(axis=0) == pytest.approx(np.array(size) / 2, abs=1e-7)
    core_half = np.array(size) / 2 - margin
    outside = np.maximum(np.abs(p) - core_half, 0.0)
    assert np.linalg.norm(outside, axis=1) == pytest.approx(np.full(len(p), margin), abs=1e-7)
    # the cone: base at -length/2, apex at +length/2 along its axis, radius at the base
    c = _geom_surface_points(m, d, g["target-shape1-cone"]) - np.array(cone["position"])
    local = c @ rotation_matrix(np.array(cone["orientation"]))
    assert local[:, 2].min() == pytest.approx(-0.025, abs=1e-7)
    assert local[:, 2].max() == pytest.approx(0.025, abs=1e-7)
    assert np.hypot(local[:, 0], local[:, 1]).max() == pytest.approx(0.03, abs=1e-6)
    # the mesh: its two coplanar triangles (a square) are one flat piece, a prism of 8 vertices
    # whose front face is the square, its back behind it (-x: the winding's normal is +x)
    q = _geom_surface_points(m, d, g["target-shape2-tri-piece0"])
    assert len(q) == 8
    assert np.sort(q[:, 0]) == pytest.approx([0.3 - ContactMatch().mesh_thickness] * 4 + [0.3] * 4, abs=1e-7)
    assert "target-shape2-tri-piece1" not in g
    # every servicer geom meets every target geom
    assert m.npair == 2 * 4
    # the facility's fixed mockup: a half-space is MuJoCo's plane
    xml_fixed, _ = write_mjcf(s, 1e-4, fixed_target=True)
    mf = mujoco.MjModel.from_xml_string(xml_fixed)
    ground = mujoco.mj_name2id(mf, mujoco.mjtObj.mjOBJ_GEOM, "target-shape3-ground")
    assert mf.geom_type[ground] == mujoco.mjtGeom.mjGEOM_PLANE


def test_half_space_plane_sign(core):
    """A half-space written as MuJoCo's plane (the facility's fixed mockup) pushes a sphere
    inside it out along the half-space's normal, with the depth the scenario's law sees."""
    from hilcontact.mujoco.facility import MujocoContact

    n = np.array([-1.0, 0.2, 0.1]) / np.linalg.norm([-1.0, 0.2, 0.1])
    s = _shape_scene([{"name": "ground", "kind": "half-space", "position": [0.04, 0.0, 0.0], "normal": n.tolist()}],
                     **{"facility.kind": "mujoco", "contact.friction.kinetic": 0.0, "contact.friction.static": 0.0})
    engine = MujocoContact(s)
    depth = 1e-4
    # the ball's centre (body frame [1, 0, 0]) placed radius − depth above the plane
    centre = np.array([0.04, 0.0, 0.0]) + (0.02 - depth) * n
    on_rod, _, _ = engine.contact(centre - np.array([1.0, 0.0, 0.0]), [1, 0, 0, 0], [0, 0, 0], [0, 0, 0])
    assert on_rod / np.linalg.norm(on_rod) == pytest.approx(n, abs=1e-9)
    assert np.linalg.norm(on_rod) == pytest.approx(s.contact.stiffness * depth, rel=1e-3)


def _check_shapes(rows, velocity=VELOCITY_TOLERANCE, impulse=IMPULSE_TOLERANCE, episodes=1):
    """As _check, with the shapes' whole impulse vector too (their normal part is a vector)."""
    _check(rows, velocity, impulse, episodes)
    assert rows[0]["episodes"][0] == rows[0]["episodes"][1], rows[0]
    for row in rows[:episodes]:
        assert row["impulse_error"] <= impulse, row


def test_crosscheck_box_landing_on_a_face(core):
    """A sharp cube lands flat on a half-space: four corner points at once in both engines (the
    same summed stiffness), no rotation in either."""
    rows = cc.run_case(_case("box on a face"))
    _check_shapes(rows, velocity=1e-3, impulse=1e-3)
    assert max(rows[0]["angular_velocity"]) < 1e-9


def test_crosscheck_box_landing_with_friction(core):
    """The cube landing obliquely (10 mm/s sideways) with μ = 0.2: friction on its four corners
    stops the sideways slip of the face (0.73 N·s, the slip's 10 mm/s times the 73 kg effective
    mass at the face: the servicer turns about its centre 1 m behind)."""
    rows = cc.run_case(_case("box on a face mu=0.2"))
    _check_shapes(rows)
    assert rows[0]["tangential_impulse"] > 0.05 * rows[0]["normal_impulse"][0]


@pytest.mark.parametrize("name", ["cylinder on an edge", "cylinder on an edge rounded", "cylinder on an edge mu=0.2",
                                  "cone on a half-space mu=0.2"])
def test_crosscheck_cylinder_on_an_edge(core, name):
    """rod-in-frame's tilted rod across the front bar's edge: one point in both engines (MuJoCo's
    multi-point convex collision off), sharp or rounded by 2 mm (MuJoCo: hulls of the rounded
    surfaces), with and without friction; a rounded cone's apex on a half-space (one point)."""
    rows = cc.run_case(_case(name))
    _check_shapes(rows, velocity=5e-3, impulse=5e-3)


def test_crosscheck_cylinder_on_an_edge_multiccd_differs(core):
    """What the first cross-check of rod-in-frame met: MuJoCo's multi-point convex collision
    touches a hull's facet crossing the edge at both ends of the segment (two full springs where
    the scenario's law has one point), and its own cylinder against a box gives the same point
    twice: the contact is twice as stiff and the rebound far off."""
    rows = cc.run_case(_case("cylinder on an edge"), match=ContactMatch(multiccd=True))
    assert rows[0]["velocity_error"] > 0.05
    rows = cc.run_case(_case("cylinder on an edge"), match=ContactMatch(cylinder_primitive=True, multiccd=True))
    assert rows[0]["velocity_error"] > 0.05


@pytest.mark.parametrize("name,tolerance", [("probe-drogue mu_s=mu_k", 1e-3), ("probe-drogue", None)])
def test_crosscheck_probe_drogue(core, name, tolerance):
    """The capsule probe strikes the drogue's mesh (coplanar triangle pairs merged into one flat
    prism each in MuJoCo) and slides with friction: matched within the targets, far inside them
    without the Stribeck peak."""
    rows = cc.run_case(_case(name))
    if tolerance is None:
        _check_shapes(rows)
    else:
        _check_shapes(rows, velocity=tolerance, impulse=tolerance)
    assert rows[0]["tangential_impulse"] > 0.0


@pytest.mark.parametrize("name", ["rod-in-frame", "rod-in-frame margin 0"])
def test_crosscheck_rod_in_frame(core, name):
    """The preset (2 mm rounded rod and bars: MuJoCo's hulls of the rounded surfaces, μ_k 0.2,
    μ_s 0.25) and its sharp variant: the edge then the corner, one episode in both engines,
    within the targets."""
    rows = cc.run_case(_case(name))
    _check_shapes(rows)
    assert rows[0]["episodes"] == (1, 1)


def test_mjcf_friction_per_material_pair(core):
    """[[contact.friction.pairs]]: each <pair> takes its shapes' materials' coefficients (either
    order), every other pair [contact.friction]'s; the cone's μ is max(μ_s, μ_k) when the
    friction follows the sliding speed (never reached), μ_k when Coulomb is the cone's."""
    case = _case("rod-in-frame two materials")
    s = hc.load_scenario(case.preset, dict(case.overrides))
    for match, front, side in ((ContactMatch(), 0.35, 0.25), (ContactMatch(track_sliding=False), 0.35, 0.2)):
        xml, matched = write_mjcf(s, 1e-4, match=match)
        m = mujoco.MjModel.from_xml_string(xml)
        names = [(mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, m.pair_geom1[j]),
                  mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, m.pair_geom2[j])) for j in range(m.npair)]
        target = [a if a.startswith("target") else b for a, b in names]
        mu = {t.split("-")[-1]: m.pair_friction[j, 0] for j, t in enumerate(target)}
        assert mu == pytest.approx({"front": front, "rear": side, "left": side, "right": side}, rel=1e-12)
        assert [p for p in matched.pair_friction] == [(0.35, 0.35), (0.2, 0.25), (0.2, 0.25), (0.2, 0.25)]
    # with tracking, each pair's viscous slope is its own μ_s: bronze's 0.35 against steel's 0.25
    slopes = matched.pair_solreffriction(np.ones(4), np.zeros(4))
    assert slopes[0] / slopes[1] == pytest.approx(0.35 / 0.25, rel=1e-12)


def test_crosscheck_two_materials(core):
    """rod-in-frame with a bronze front bar (μ 0.35) and steel side bars (0.2/0.25): matched
    within the targets; the pair's coefficient acts in both engines (the tangential impulse is
    not the single-material preset's)."""
    rows = cc.run_case(_case("rod-in-frame two materials"))
    _check_shapes(rows)
    steel = cc.run_case(_case("rod-in-frame"))
    assert abs(rows[0]["tangential_impulse"] - steel[0]["tangential_impulse"]) > 0.05 * steel[0]["tangential_impulse"]


def test_mujoco_facility_with_shapes_at_zero_delay(core):
    """rod-in-frame on the MuJoCo facility (the mockup's rounded bars as hulls, fixed in MuJoCo's
    world): every collision's CoV and CoF within the targets of the model facility's, and as
    faithful; probe-drogue's four collisions too (the mesh's edge contacts dropped where a face of
    the same mesh touches, as the core does)."""
    over = {"facility.robot_delay": 0.0}
    model = hc.simulate(hc.load_scenario("rod-in-frame", over))
    mj = hc.simulate(hc.load_scenario("rod-in-frame", {**over, "facility.kind": "mujoco"}))
    assert model.status == mj.status == "ok"
    a, b = _collisions(model), _collisions(mj)
    assert len(a) == len(b) >= 3
    for (cov_m, cof_m), (cov_j, cof_j) in zip(a, b):
        assert abs(cov_j - cov_m) <= VELOCITY_TOLERANCE
        assert abs(cof_j - cof_m) <= IMPULSE_TOLERANCE
    over = {"facility.robot_delay": 0.0}
    model = hc.simulate(hc.load_scenario("probe-drogue", over))
    mj = hc.simulate(hc.load_scenario("probe-drogue", {**over, "facility.kind": "mujoco"}))
    a, b = _collisions(model), _collisions(mj)
    assert len(a) == len(b) == 4
    for (cov_m, cof_m), (cov_j, cof_j) in zip(a, b):
        assert abs(cov_j - cov_m) <= VELOCITY_TOLERANCE
        assert abs(cof_j - cof_m) <= IMPULSE_TOLERANCE


def test_crosscheck_probe_drogue_mesh_faces_only(core):
    """The probe's tip in the narrow part of the cone touches several facets at once. With the
    core's rule (a mesh's edge contacts dropped where a face of the same mesh touches) MuJoCo's
    second episode is the reference's, within the targets; without it every touched prism is a
    full spring and MuJoCo's contact is stiffer: the episode ends more than 10 ms early."""
    case = _case("probe-drogue")
    case = cc.Case(case.name, case.preset, {**case.overrides, "simulation.duration": 4.5})
    rows = cc.run_case(case)
    _check_shapes(rows, episodes=2)
    assert rows[1]["episodes"] == (2, 2)
    every = cc.run_case(case, match=ContactMatch(mesh_faces_only=False))
    assert every[1]["end"] - every[1]["mujoco_end"] > 0.010
