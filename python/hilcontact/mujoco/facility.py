"""The facility engine ``facility.kind = "mujoco"``: the hardware side of a simulated HIL run is
MuJoCo (the paper's NX/Motion role), the virtual side and the compensators unchanged.

Each control tick the core's loop (``_core.simulate_facility``, ``crates/py/src/facility.rs``)
moves the robot as the facility model's robot does (pure delay ``facility.robot_delay``, the
optional servo lag), then asks :class:`MujocoContact` for the contact at the robot's actual pose:
the servicer's pose and twist are set in MuJoCo (the mockup, the target's walls, is fixed in
MuJoCo's world: the frame ``t``), MuJoCo finds the contacts and their forces (its soft contact
matched to the scenario's law, :mod:`hilcontact.mujoco.mjcf`), and the wrench on the mockup is
summed from every contact at its own point, about the sensor origin. The sensor (its delay,
noise, quantisation, seed) is the facility model's, so that only the contact differs.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from ..errors import ScenarioError
from . import require
from .mjcf import ContactMatch, MatchedContact, MeshFaceFilter, mesh_faces, rotation_matrix, write_mjcf

__all__ = ["MujocoContact", "simulate_facility"]


class MujocoContact:
    """The contact between the robot's rod and the mockup, computed by MuJoCo, for the core's
    facility loop (``contact_flat``). ``scenario``: a resolved scenario; its
    ``facility.mujoco_model`` (an MJCF file: a free body named ``servicer`` whose geoms are the
    rod, every other geom fixed in the world frame = ``t``) or, when empty, the model written from
    the scenario (:func:`~hilcontact.mujoco.mjcf.write_mjcf` with the target fixed)."""

    def __init__(self, scenario: Any, match: ContactMatch | None = None) -> None:
        mj = require()
        self._mj = mj
        path = scenario.facility.mujoco_model
        self.matched: MatchedContact | None = None
        self._faces: MeshFaceFilter | None = None
        if path:
            try:
                self.model = mj.MjModel.from_xml_path(os.fspath(path))
            except (ValueError, OSError) as exc:
                raise ScenarioError(f"facility.mujoco_model: {path}: {' '.join(str(exc).split())}") from None
        else:
            match = match or ContactMatch()
            xml, self.matched = write_mjcf(scenario, float(scenario.facility.mujoco_timestep),
                                           match=match, fixed_target=True)
            self.xml = xml
            self.model = mj.MjModel.from_xml_string(xml)
            if match.mesh_faces_only:
                self._faces = MeshFaceFilter(mj, self.model, mesh_faces(scenario))
        m = self.model
        body = mj.mj_name2id(m, mj.mjtObj.mjOBJ_BODY, "servicer")
        if body < 0 or m.body_jntnum[body] != 1 or m.jnt_type[m.body_jntadr[body]] != mj.mjtJoint.mjJNT_FREE:
            raise ScenarioError("facility.mujoco_model: the model needs a body named 'servicer' with a free joint (the rod's body)")
        self._body = body
        self._qpos = int(m.jnt_qposadr[m.body_jntadr[body]])
        self._dof = int(m.jnt_dofadr[m.body_jntadr[body]])
        self.data = mj.MjData(m)
        self._sensor = np.asarray(scenario.facility.sensor_position, dtype=float)
        self._f6 = np.zeros(6)
        self._track = self.matched is not None and self.matched.tracks
        #: MuJoCo contacts at the last call.
        self.contacts = 0
        #: The friction (tangential) part of the force on the rod at the last call, ``t``, N.
        self.friction = np.zeros(3)

    def _forces(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Force on the rod, force on the mockup and its moment about the sensor origin (``t``),
        and each pair's normal force, for the state in ``data``."""
        mj, m, d = self._mj, self.model, self.data
        if self._faces is not None and self._faces.pieces:
            self._faces.forward(m, d)
        else:
            mj.mj_forward(m, d)
        on_rod = np.zeros(3)
        friction = np.zeros(3)
        moment = np.zeros(3)
        normal = np.zeros(max(m.npair, 1))
        slide = np.zeros(max(m.npair, 1))
        points = np.zeros(max(m.npair, 1))
        for i in range(d.ncon):
            c = d.contact[i]
            if c.efc_address < 0 or c.exclude:
                continue
            rod1 = m.geom_bodyid[c.geom1] == self._body
            rod2 = m.geom_bodyid[c.geom2] == self._body
            if rod1 == rod2:
                continue
            mj.mj_contactForce(m, d, i, self._f6)
            frame = c.frame.reshape(3, 3)
            on_geom2 = frame.T @ self._f6[:3]
            tangential = frame[1:].T @ self._f6[1:3]
            f = on_geom2 if rod2 else -on_geom2
            on_rod += f
            friction += tangential if rod2 else -tangential
            moment += np.cross(c.pos - self._sensor, -f)
            if self._track:
                pair = self._pair_of(c)
                normal[pair] += self._f6[0]
                points[pair] += 1.0
                if c.dim >= 3:
                    a = c.efc_address
                    slide[pair] += self._f6[0] * float(np.hypot(d.efc_vel[a + 1], d.efc_vel[a + 2]))
        self.contacts = int(d.ncon)
        self.friction = friction
        self._speed = np.divide(slide, normal, out=np.zeros_like(slide), where=normal > 0.0)
        # a pair's parameters apply to each of its points: its mean normal force per point
        return on_rod, moment, np.divide(normal, points, out=np.zeros_like(normal), where=points > 0)

    def _pair_of(self, contact: Any) -> int:
        m = self.model
        for j in range(m.npair):
            if {m.pair_geom1[j], m.pair_geom2[j]} == {contact.geom1, contact.geom2}:
                return j
        return 0

    def contact(self, position: Any, orientation: Any, velocity: Any, angular_velocity: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The contact for the servicer's motion relative to ``t`` (CoM position m, attitude
        [w, x, y, z] servicer to ``t``, CoM velocity m/s, angular velocity rad/s, all in ``t``):
        the force on the rod (N), the force on the mockup (N) and its moment about the sensor
        origin (N·m), all in ``t``."""
        d = self.data
        q = np.asarray(orientation, dtype=float)
        d.qpos[self._qpos:self._qpos + 3] = position
        d.qpos[self._qpos + 3:self._qpos + 7] = q
        d.qvel[self._dof:self._dof + 3] = velocity
        d.qvel[self._dof + 3:self._dof + 6] = rotation_matrix(q).T @ np.asarray(angular_velocity, dtype=float)
        if self._track:
            # friction's viscous slope follows the normal force and the sliding speed
            # (docs/mujoco.md): a first pass gives each pair's normal force and sliding speed at
            # this state, the second the forces with that slope
            self.model.pair_solreffriction[:, 1] = 0.0
            _, _, normal = self._forces()
            npair = self.model.npair
            self.model.pair_solreffriction[:, 1] = self.matched.pair_solreffriction(normal[:npair], self._speed[:npair])
        on_rod, moment, _ = self._forces()
        return on_rod, -on_rod, moment

    def contact_flat(self, motion: Any) -> list[float]:
        """:meth:`contact` for the core (``crates/py/src/facility.rs``): ``motion`` the 13
        numbers position, quaternion, velocity, angular velocity; returns 12 numbers: the force on
        the rod, the force on the mockup, its moment, and the friction part of the force on the
        rod (:attr:`friction`, the tangential parts of MuJoCo's contact forces)."""
        on_rod, force, moment = self.contact(motion[0:3], motion[3:7], motion[7:10], motion[10:13])
        return [*on_rod.tolist(), *force.tolist(), *moment.tolist(), *self.friction.tolist()]


def simulate_facility(scenario: Any, match: ContactMatch | None = None) -> dict[str, Any]:
    """``_core.simulate_facility`` of a resolved scenario with a :class:`MujocoContact`: what
    ``_core.simulate`` returns (``timeseries``, ``reference``, ``metrics`` as JSON)."""
    from ..native import core

    engine = MujocoContact(scenario, match)
    return core().simulate_facility(scenario.to_json(), engine)
