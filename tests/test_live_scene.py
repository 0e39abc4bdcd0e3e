"""A shape scenario's recorded scene, read as a viewer reads it (mcap_ros2): every contact point
drawn with its own normal and friction arrows (1 mm/N), and the arrows add up to the contact
force of the run's time series at that tick (crates/rt/src/output/scene.rs; the Rust side
checks the points against the core's in crates/rt/tests/live_scene.rs)."""
from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

import hilcontact as hc

mcap_ros2_reader = pytest.importorskip("mcap_ros2.reader")

POINTS = 1000  # marker id of the first point; + 1 its normal arrow, + 2 its friction arrow
SCALE = 0.001  # m/N


def test_a_shape_scene_s_arrows_add_up_to_the_recorded_contact_force(tmp_path):
    path = tmp_path / "rod-in-frame.mcap"
    run = hc.simulate("rod-in-frame", outputs={"mcap": {"path": str(path)}})
    assert run.mcap["complete"] and run.mcap["scene_points_dropped"] == 0
    ts = run.timeseries.set_index("time")
    period = float(ts.index[1] - ts.index[0])
    touching = most = 0
    for m in mcap_ros2_reader.read_ros2_messages(str(path), topics=["/hil/scene"]):
        markers = {x.id: x for x in m.ros_msg.markers}
        stamp = m.ros_msg.markers[0].header.stamp
        k = round((stamp.sec + stamp.nanosec * 1e-9) / period)
        recorded = ts.iloc[k][["contact_force_x", "contact_force_y", "contact_force_z"]].to_numpy(float)

        def arrow(i):
            a, b = markers[i].points
            return np.array([b.x - a.x, b.y - a.y, b.z - a.z]) / SCALE

        total = arrow(3)  # the rod tip's part against the walls (none here)
        shown = [i for i in range(POINTS, POINTS + 48, 3) if markers[i].color.a == 1.0]
        for i in shown:
            normal, friction = arrow(i + 1), arrow(i + 2)
            assert abs(normal @ friction) <= 1e-6 * (1 + np.linalg.norm(normal) * np.linalg.norm(friction))
            total += normal + friction
        assert np.linalg.norm(total - recorded) <= 1e-6 * (1 + np.linalg.norm(recorded)), (k, total, recorded)
        touching += bool(shown)
        most = max(most, len(shown))
    assert touching > 10 and most >= 2, (touching, most)



def _quat_mul(a, b):
    """The product a·b of quaternions (x, y, z, w)."""
    (ax, ay, az, aw), (bx, by, bz, bw) = a, b
    return np.array([
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    ])


def _rotate(q, v):
    """v rotated by the unit quaternion q = (x, y, z, w)."""
    u, w = np.asarray(q[:3]), q[3]
    return v + 2.0 * np.cross(u, np.cross(u, v) + w * v)


def test_a_shape_scene_draws_the_rod_and_the_frame_s_bars_with_their_dimensions(tmp_path):
    """rod-in-frame: the rod (a cylinder, id 2000) at the actual servicer's frame of the same
    message time (/tf servicer_actual) ∘ its pose in the body frame, the four bars (cubes,
    2003-2012) where the preset puts them, each body semi-transparent in its own colour."""
    path = tmp_path / "rod-in-frame.mcap"
    run = hc.simulate("rod-in-frame", outputs={"mcap": {"path": str(path)}})
    assert run.mcap["scene_meshes_boxed"] == 0
    preset = tomllib.loads((Path(hc.__file__).parent / "scenarios" / "rod-in-frame.toml").read_text())
    rod = preset["servicer"]["shapes"][0]
    bars = preset["target"]["shapes"]
    w, x, y, z = rod["orientation"]
    rod_q = np.array([x, y, z, w]) / np.linalg.norm([x, y, z, w])
    frames = {}
    for m in mcap_ros2_reader.read_ros2_messages(str(path), topics=["/tf"]):
        for t in m.ros_msg.transforms:
            if t.child_frame_id == "servicer_actual":
                tr, r = t.transform.translation, t.transform.rotation
                frames[m.log_time_ns] = (np.array([tr.x, tr.y, tr.z]), np.array([r.x, r.y, r.z, r.w]))
    n = 0
    for m in mcap_ros2_reader.read_ros2_messages(str(path), topics=["/hil/scene"]):
        markers = {x.id: x for x in m.ros_msg.markers}
        origin, q = frames[m.log_time_ns]
        cyl = markers[2000]
        assert cyl.type == 3
        assert (cyl.scale.x, cyl.scale.y, cyl.scale.z) == (2 * rod["radius"], 2 * rod["radius"], rod["length"])
        at = np.array([cyl.pose.position.x, cyl.pose.position.y, cyl.pose.position.z])
        assert np.linalg.norm(at - (origin + _rotate(q, np.array(rod["position"])))) < 1e-9
        o = cyl.pose.orientation
        assert abs(abs(np.dot([o.x, o.y, o.z, o.w], _quat_mul(q, rod_q))) - 1) < 1e-9
        for j, bar in enumerate(bars):
            box = markers[2000 + 3 * (j + 1)]
            assert box.type == 1 and [box.scale.x, box.scale.y, box.scale.z] == bar["size"]
            assert [box.pose.position.x, box.pose.position.y, box.pose.position.z] == bar["position"]
            assert box.color.a == cyl.color.a and 0 < box.color.a < 1
            assert (box.color.r, box.color.g, box.color.b) != (cyl.color.r, cyl.color.g, cyl.color.b)
        n += 1
    assert n > 50 and len(frames) == n
