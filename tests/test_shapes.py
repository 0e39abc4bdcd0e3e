"""Collision shapes in scenario files (issue 21): the presets with shapes, meshes read from STL
and OBJ files relative to the scenario file, and the bad input a user gives them (one line
naming the key or the file, exit 2, nothing written)."""

from __future__ import annotations

import struct

import numpy as np
import pytest
import tomli_w

import hilcontact as hc
from test_cli import assert_one_error_line, invoke

SHORT = ("--set", "simulation.duration=0.3", "--no-plots")


def cube_triangles() -> tuple[list[list[float]], list[list[int]]]:
    """A unit cube centred on the origin: 8 vertices, 12 triangles (outward)."""
    v = [[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)]
    faces = [
        [0, 1, 3, 2], [4, 6, 7, 5],  # x = -0.5, +0.5
        [0, 4, 5, 1], [2, 3, 7, 6],  # y
        [0, 2, 6, 4], [1, 5, 7, 3],  # z
    ]
    tris = [t for a, b, c, d in faces for t in ([a, b, c], [a, c, d])]
    return v, tris


def write_binary_stl(path, vertices, triangles) -> None:
    with open(path, "wb") as f:
        f.write(b"\0" * 80 + struct.pack("<I", len(triangles)))
        for t in triangles:
            f.write(struct.pack("<3f", 0.0, 0.0, 0.0))
            for i in t:
                f.write(struct.pack("<3f", *vertices[i]))
            f.write(b"\0\0")


def write_obj(path, vertices, triangles) -> None:
    lines = [f"v {x} {y} {z}" for x, y, z in vertices] + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in triangles]
    path.write_text("\n".join(lines) + "\n")


def mesh_scene(file: str, scale: float = 0.1) -> dict:
    """A sphere probe (the servicer's) flying at a target mesh (a cube of `scale` m) 20 mm away."""
    raw = hc.load_scenario("paper-table1").to_dict()
    raw["walls"] = []
    raw["name"] = "mesh-scene"
    raw["servicer"]["position"] = [-0.5 * scale - 0.03, 0.01, 0.005]
    raw["servicer"]["shapes"] = [{"kind": "sphere", "radius": 0.01}]
    raw["target"]["shapes"] = [{"kind": "mesh", "file": file, "scale": scale}]
    raw["rod"]["tip"] = [0.01, 0.0, 0.0]
    raw["simulation"]["duration"] = 2.0
    return raw


def test_the_shape_presets_load_with_their_meshes():
    drogue = hc.load_scenario("probe-drogue")
    shape = drogue.target.shapes[0]
    assert shape.kind == "mesh" and shape.file == "probe-drogue-cone.obj"
    assert len(shape.vertices) == 3 * 96 and len(shape.triangles) == 4 * 96
    # the resolved scenario carries the mesh: it loads again without the file
    again = hc.Scenario.from_toml(drogue.to_toml())
    assert again == drogue
    rod = hc.load_scenario("rod-in-frame")
    assert [s.name for s in rod.target.shapes] == ["front", "rear", "left", "right"]
    assert rod.contact.friction.kinetic == 0.2


@pytest.mark.parametrize("writer,suffix", [(write_binary_stl, "stl"), (write_obj, "obj")])
def test_a_mesh_file_beside_the_scenario_is_read_and_met_like_the_box(core, tmp_path, writer, suffix):
    v, t = cube_triangles()
    writer(tmp_path / f"cube.{suffix}", v, t)
    path = tmp_path / "scene.toml"
    path.write_text(tomli_w.dumps(mesh_scene(f"cube.{suffix}")))
    mesh = hc.load_scenario(path, {"facility.robot_delay": 0.0})
    assert len(mesh.target.shapes[0].triangles) == 12
    box = hc.load_scenario(
        mesh,
        {"target.shapes": [{"kind": "box", "size": [0.1, 0.1, 0.1], "margin": 1e-9}]},
    )
    a, b = hc.simulate(mesh), hc.simulate(box)
    va = a.reference[["tip_velocity_x", "tip_velocity_y", "tip_velocity_z"]].to_numpy()[-1]
    vb = b.reference[["tip_velocity_x", "tip_velocity_y", "tip_velocity_z"]].to_numpy()[-1]
    assert va[0] < 0.0, "the sphere rebounded off the mesh"
    assert np.allclose(va, vb, rtol=1e-6, atol=1e-9), (va, vb)


BAD_MESHES = [
    ("missing.stl", None, ["target.shapes[0].file", "cannot read mesh 'missing.stl'"]),
    ("garbage.stl", b"solid nonsense\nthis is not stl\n", ["target.shapes[0].file", "garbage.stl", "not a valid STL"]),
    ("empty.obj", b"# nothing\n", ["target.shapes[0]", "the mesh is empty", "empty.obj"]),
    ("cube.ply", b"ply\n", ["target.shapes[0].file", "unknown mesh format '.ply'"]),
    ("fan.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nv 1 1 1\nf 1 2 3\nf 1 2 4\nf 1 2 5\n",
     ["target.shapes[0].triangles[2]", "non-manifold", "fan.obj"]),
    ("flat.obj", b"v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", ["target.shapes[0].triangles[0]", "degenerate"]),
]


@pytest.mark.parametrize("name,content,fragments", BAD_MESHES, ids=[m[0] for m in BAD_MESHES])
def test_a_bad_mesh_is_one_line_naming_the_key_and_the_file(tmp_path, name, content, fragments):
    if content is not None:
        (tmp_path / name).write_bytes(content)
    path = tmp_path / "scene.toml"
    path.write_text(tomli_w.dumps(mesh_scene(name)))
    result = invoke("run", str(path), "--out", str(tmp_path / "out"), *SHORT[2:], cwd=tmp_path)
    assert_one_error_line(result, *fragments)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    "sets,fragments",
    [
        (["servicer.position=[-1.0, 0.0, 0.0]", "servicer.velocity=[0.0, 0.0, 0.0]"],
         ["servicer.shapes[0]", "'rod' and target.shapes[", "start interpenetrating"]),
        (["contact.friction.kinetic=3"], ["contact.friction.kinetic", "between 0 and 2"]),
        (["contact.friction.kinetic=0.3", "contact.friction.static=0.1"], ["contact.friction.static", "must not be below"]),
        (["target.shapes[0].margin=0.05"], ["target.shapes[0].margin", "below half"]),
        (["servicer.shapes[0].kind=\"half-space\"", "servicer.shapes[0].normal=[1, 0, 0]"], ["servicer.shapes", "half-space"]),
    ],
    ids=["interpenetrating", "friction-range", "static-below-kinetic", "margin", "half-space-on-servicer"],
)
def test_bad_shape_values_are_one_line(tmp_path, sets, fragments):
    if sets[0].startswith("servicer.position"):
        # the rod pushed into the front bar at the start
        sets = ["servicer.position=[-0.985, 0.0, 0.0]", *sets[1:]]
    args = [a for s in sets for a in ("--set", s)]
    result = invoke("run", "rod-in-frame", *args, "--out", str(tmp_path / "out"), *SHORT, cwd=tmp_path)
    assert_one_error_line(result, *fragments)
    assert list(tmp_path.iterdir()) == []


def test_rod_in_frame_touches_an_edge_and_a_corner_with_friction(core):
    run = hc.simulate(hc.load_scenario("rod-in-frame", {"simulation.duration": 1.0, "facility.robot_delay": 0.0}))
    ref = run.reference
    # the front bar first, then the front and the left bar at once (the corner)
    assert ref["friction_work"].iloc[-1] > 0.0
    fy = ref["contact_force_y"].to_numpy()
    fx = ref["contact_force_x"].to_numpy()
    both = (np.abs(fx) > 1.0) & (fy < -1.0)
    assert both.any(), "no moment with the rod on the front and the side bar at once"
    assert (ref["friction_force_x"].abs() + ref["friction_force_y"].abs() + ref["friction_force_z"].abs()).max() > 0.0


def pairs_scene(tmp_path, pairs: list[dict]) -> str:
    """`rod-in-frame` with its rod of `steel` and its bars of `steel` (the two front bars) and
    `bronze`, a `[[contact.friction.pairs]]` list, written to a file."""
    raw = hc.load_scenario("rod-in-frame").to_dict()
    for shape in raw["servicer"]["shapes"]:
        shape["material"] = "steel"
    for i, shape in enumerate(raw["target"]["shapes"]):
        shape["material"] = "steel" if i < 2 else "bronze"
    raw["contact"]["friction"]["pairs"] = pairs
    raw["simulation"]["duration"] = 0.3
    path = tmp_path / "pairs.toml"
    path.write_text(tomli_w.dumps(raw))
    return str(path)


def test_friction_per_material_pair_loads_from_a_scenario_file(core, tmp_path):
    path = pairs_scene(tmp_path, [{"materials": ["bronze", "steel"], "kinetic": 0.4, "static": 0.5}])
    scenario = hc.load_scenario(path)
    assert scenario.to_dict()["contact"]["friction"]["pairs"] == [
        {"materials": ["bronze", "steel"], "kinetic": 0.4, "static": 0.5}
    ]
    assert hc.load_scenario("rod-in-frame").to_dict()["contact"]["friction"]["pairs"] == []


@pytest.mark.parametrize(
    "pairs,fragments",
    [
        ([{"materials": ["steel", "bronz"], "kinetic": 0.2}], ["contact.friction.pairs[0].materials", "bronz", "bronze, steel"]),
        ([{"materials": ["steel", "bronze"], "kinetic": 0.3, "static": 0.2}], ["contact.friction.pairs[0].static", "must not be below"]),
        ([{"materials": ["steel", "bronze"], "kinetic": 3}], ["contact.friction.pairs[0].kinetic", "between 0 and 2"]),
        ([{"materials": ["steel"], "kinetic": 0.2}], ["contact.friction.pairs[0].materials"]),
        ([{"materials": ["steel", "bronze"]}, {"materials": ["bronze", "steel"]}], ["contact.friction.pairs[1].materials", "twice"]),
        ([{"materials": ["steel", "bronze"], "mu": 0.2}], ["contact.friction.pairs[0]", "mu"]),
    ],
    ids=["unknown-material", "static-below-kinetic", "range", "one-material", "twice", "unknown-key"],
)
def test_bad_material_pairs_are_one_line(tmp_path, pairs, fragments):
    path = pairs_scene(tmp_path, pairs)
    result = invoke("run", path, "--out", str(tmp_path / "out"), "--no-plots", cwd=tmp_path)
    assert_one_error_line(result, *fragments)
    assert not (tmp_path / "out").exists()


def test_a_shape_value_out_of_range_names_its_range(tmp_path):
    result = invoke("run", "rod-in-frame", "--set", "servicer.shapes[0].radius=200",
                    "--out", str(tmp_path / "out"), *SHORT, cwd=tmp_path)
    assert_one_error_line(result, "servicer.shapes[0].radius", "between 0 and 100")
