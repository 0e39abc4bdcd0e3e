"""A shape scenario's recorded scene, read as a viewer reads it (mcap_ros2): every contact point
drawn with its own normal and friction arrows (1 mm/N), and the arrows add up to the contact
force of the run's time series at that tick (crates/rt/src/output/scene.rs; the Rust side
checks the points against the core's in crates/rt/tests/live_scene.rs)."""
from __future__ import annotations

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
