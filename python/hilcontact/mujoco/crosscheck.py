"""The MuJoCo cross-check: the scene of a scenario simulated by MuJoCo (no facility, no delay)
against the ideal reference of the core, contact episode by contact episode (docs/mujoco.md).

Per episode (an interval where a contact force acts, matched by order), at the first sample
``5 ms`` after both engines' episodes ended:

- the rebound velocity vector of the rod tip relative to the target (``t``):
  ``velocity_error = |v_mj − v_ref| / |v_ref|``;
- the servicer's angular velocity relative to the target (``t``):
  ``angular_velocity_error = |ω_mj − ω_ref| / max(|ω_ref|, OMEGA_FLOOR)``;
- the angular impulse on the target's frame about the sensor origin ``H = ∫M dt`` (what turns
  both bodies: the reference records only their relative angular velocity):
  ``angular_impulse_error = |H_mj − H_ref| / |H_ref|``;
- the contact impulse ``J = ∫F dt`` on the rod (``t``): its normal part along each wall the
  episode touched (``J·n``) and its tangential part (``J − Σ(J·n)n`` for one wall), with
  ``normal_impulse_error = |J_n,mj − J_n,ref| / |J_n,ref|`` (the largest over the walls) and
  ``tangential_impulse_error = |J_t,mj − J_t,ref| / |J_ref|`` (against the whole impulse:
  near-sticking contacts have a small ``J_t``).

:data:`CASES` are the cases of the table in docs/mujoco.md (``python scripts/mujoco_crosscheck.py``
prints it); the test suite runs a few (tests/test_mujoco.py).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import require
from .mjcf import ContactMatch, MatchedContact, MeshFaceFilter, mesh_faces, rotation_matrix, wall_geom_name, write_mjcf

__all__ = ["CASES", "Case", "Episode", "MujocoTrace", "crosscheck", "simulate_mujoco", "table"]

#: Time after both engines' episodes ended at which rebound velocities are compared, s.
AFTER = 0.005

#: The angular velocity error's floor, rad/s: a contact that turns nothing (a cube landing flat:
#: both engines leave |ω| ~ 1e-16 rad/s) is compared against this, not against rounding.
OMEGA_FLOOR = 1e-6


@dataclass(frozen=True)
class Case:
    """A cross-check case: a preset with overrides (dotted keys, as ``--set`` takes them)."""

    name: str
    preset: str
    overrides: Mapping[str, Any] = field(default_factory=dict)
    #: What the case is for, one line.
    description: str = ""
    #: :class:`ContactMatch` fields for this case (e.g. ``{"round_edges": False}``).
    match: Mapping[str, Any] = field(default_factory=dict)


#: The corner: two perpendicular walls (front x = 10 mm facing -x, side y = 102 mm facing -y)
#: that the tip of oblique-6dof reaches at nearly the same time, so that both push at once.
_CORNER = {
    "walls": [
        {"name": "front", "point": [0.010, 0.0, 0.0], "normal": [-1.0, 0.0, 0.0]},
        {"name": "side", "point": [0.0, 0.102, 0.0], "normal": [0.0, -1.0, 0.0]},
        {"name": "rear", "point": [-0.010, 0.0, 0.0], "normal": [1.0, 0.0, 0.0]},
    ],
    "servicer.velocity": [0.02, 0.008, -0.001],
}

_SHORT = {"facility.robot_delay": 0.0, "simulation.duration": 0.8}

#: A sharp 100 mm cube on the servicer (its face centre the rod tip) lands flat on a half-space
#: of the target 10 mm ahead, frictionless unless a case sets μ (rod-in-frame's masses).
_BOX_ON_FACE = {
    "servicer.shapes": [{"name": "cube", "kind": "box", "size": [0.1, 0.1, 0.1], "margin": 0.0,
                         "position": [0.95, 0.0, 0.0]}],
    "target.shapes": [{"name": "ground", "kind": "half-space", "position": [0.01, 0.0, 0.0],
                       "normal": [-1.0, 0.0, 0.0]}],
    "servicer.velocity": [0.02, 0.0, 0.0],
    "contact.friction.kinetic": 0.0, "contact.friction.static": 0.0,
}

#: A cone (30 mm base radius, 100 mm long, 2 mm rounding) on the servicer, its apex ahead (+x),
#: strikes a half-space 10 mm away obliquely with friction 0.2.
_CONE = {
    "servicer.shapes": [{"name": "cone", "kind": "cone", "radius": 0.03, "length": 0.1, "margin": 0.002,
                         "position": [0.95, 0.0, 0.0], "orientation": [0.70710678, 0.0, 0.70710678, 0.0]}],
    "target.shapes": [{"name": "ground", "kind": "half-space", "position": [0.01, 0.0, 0.0],
                       "normal": [-1.0, 0.0, 0.0]}],
    "servicer.velocity": [0.02, 0.005, 0.0],
    "contact.friction.kinetic": 0.2, "contact.friction.static": 0.2,
}

_ROD = {"name": "rod", "kind": "cylinder", "radius": 0.010, "length": 0.300, "margin": 0.0,
        "position": [1.0, 0.0, 0.0], "orientation": [0.99950507, 0.01744643, 0.02617296, 0.00045685]}


def _bar(name: str, size: list[float], position: list[float], margin: float = 0.0) -> dict[str, Any]:
    return {"name": name, "kind": "box", "size": size, "position": position, "margin": margin}


#: rod-in-frame's rod, tilted 3° and 2°, against the front bar alone, moving along x: its side
#: meets the bar's upper edge at one point.
_EDGE = {
    "servicer.shapes": [_ROD],
    "target.shapes": [_bar("front", [0.040, 0.120, 0.020], [0.040, 0.0, 0.0])],
    "servicer.velocity": [0.02, 0.0, 0.0],
    "contact.friction.kinetic": 0.0, "contact.friction.static": 0.0,
}
_ROUNDED_EDGE = {
    "servicer.shapes": [{**_ROD, "margin": 0.002}],
    "target.shapes": [_bar("front", [0.040, 0.120, 0.020], [0.040, 0.0, 0.0], 0.002)],
}
#: rod-in-frame with its front bar of another material (bronze on the steel rod: μ 0.35 from
#: ``[[contact.friction.pairs]]``), the other bars steel on steel (``[contact.friction]``'s 0.2 /
#: 0.25): the edge contact and the corner take different coefficients.
_TWO_MATERIALS = {
    "servicer.shapes": [{**_ROD, "margin": 0.002, "material": "steel"}],
    "target.shapes": [{**_bar("front", [0.040, 0.120, 0.020], [0.040, 0.0, 0.0], 0.002), "material": "bronze"},
                      {**_bar("rear", [0.040, 0.120, 0.020], [-0.040, 0.0, 0.0], 0.002), "material": "steel"},
                      {**_bar("left", [0.040, 0.040, 0.020], [0.0, 0.040, 0.0], 0.002), "material": "steel"},
                      {**_bar("right", [0.040, 0.040, 0.020], [0.0, -0.040, 0.0], 0.002), "material": "steel"}],
    "contact.friction.pairs": [{"materials": ["steel", "bronze"], "kinetic": 0.35}],
}

#: rod-in-frame with sharp rod and bars (margin 0).
_SHARP_FRAME = {
    "servicer.shapes": [_ROD],
    "target.shapes": [_bar("front", [0.040, 0.120, 0.020], [0.040, 0.0, 0.0]),
                      _bar("rear", [0.040, 0.120, 0.020], [-0.040, 0.0, 0.0]),
                      _bar("left", [0.040, 0.040, 0.020], [0.0, 0.040, 0.0]),
                      _bar("right", [0.040, 0.040, 0.020], [0.0, -0.040, 0.0])],
}

#: The cases of the cross-check table (docs/mujoco.md).
CASES: tuple[Case, ...] = (
    Case("oblique frictionless", "oblique-6dof", dict(_SHORT),
         "oblique-6dof at zero delay: tilted wall, offset tip, both bodies rotate"),
    Case("oblique mu=0.1", "oblique-6dof", {**_SHORT, "contact.friction.kinetic": 0.1},
         "the same with Coulomb friction 0.1 (sliding throughout)"),
    Case("oblique mu=0.3", "oblique-6dof", {**_SHORT, "contact.friction.kinetic": 0.3},
         "the same with friction 0.3 (the tip sticks part of the time)"),
    Case("oblique mu=0.3 v_eps=0.1mm/s", "oblique-6dof",
         {**_SHORT, "contact.friction.kinetic": 0.3, "contact.friction.stick_velocity": 1e-4},
         "friction 0.3 with a regularisation ten times narrower: the law is Coulomb's while sliding"),
    Case("corner frictionless", "oblique-6dof", {**_SHORT, **_CORNER},
         "the tip in a corner: two perpendicular walls pressed at once"),
    Case("corner mu=0.2", "oblique-6dof", {**_SHORT, **_CORNER, "contact.friction.kinetic": 0.2},
         "the corner with friction 0.2"),
    Case("paper-table1", "paper-table1", {"simulation.duration": 1.0, "facility.robot_delay": 0.0},
         "the paper's 1-D case (head-on, damped contact)"),
    Case("box on a face", "rod-in-frame", {**_SHORT, **_BOX_ON_FACE},
         "a sharp 100 mm cube lands flat on a half-space: four corner points at once"),
    Case("box on a face mu=0.2", "rod-in-frame",
         {**_SHORT, **_BOX_ON_FACE, "servicer.velocity": [0.02, 0.01, 0.0], "contact.friction.kinetic": 0.2, "contact.friction.static": 0.2},
         "the cube landing obliquely, sliding with friction 0.2 on its four corners"),
    Case("cone on a half-space mu=0.2", "rod-in-frame", {**_SHORT, **_CONE},
         "a 2 mm rounded cone's apex strikes a half-space obliquely, friction 0.2 (MuJoCo: the rounded hull)"),
    Case("cylinder on an edge", "rod-in-frame", {**_SHORT, **_EDGE},
         "rod-in-frame's rod (sharp) across the front bar's edge (sharp): one point"),
    Case("cylinder on an edge rounded", "rod-in-frame", {**_SHORT, **_EDGE, **_ROUNDED_EDGE},
         "the same with 2 mm rounded edges (MuJoCo: convex hulls of the rounded surfaces)"),
    Case("cylinder on an edge mu=0.2", "rod-in-frame",
         {**_SHORT, **_EDGE, "servicer.velocity": [0.02, 0.01, 0.0], "contact.friction.kinetic": 0.2, "contact.friction.static": 0.2},
         "the sharp rod across the sharp edge, sliding along it with friction 0.2"),
    Case("rod-in-frame", "rod-in-frame", {"facility.robot_delay": 0.0, "simulation.duration": 1.5},
         "the preset: rounded rod and bars (MuJoCo: convex hulls), an edge then the corner, friction 0.2/0.25"),
    Case("rod-in-frame sharp MuJoCo", "rod-in-frame", {"facility.robot_delay": 0.0, "simulation.duration": 1.5},
         "the preset against MuJoCo's sharp cylinder and boxes (what the first cross-check did)",
         {"round_edges": False}),
    Case("rod-in-frame margin 0", "rod-in-frame",
         {"facility.robot_delay": 0.0, "simulation.duration": 1.5, "contact.friction.static": 0.2, **_SHARP_FRAME},
         "the preset with sharp rod and bars on both sides (margin 0), μ_s = μ_k = 0.2"),
    Case("rod-in-frame two materials", "rod-in-frame",
         {"facility.robot_delay": 0.0, "simulation.duration": 1.5, **_TWO_MATERIALS},
         "the preset with a bronze front bar: μ 0.35 on the edge ([[contact.friction.pairs]]), 0.2/0.25 in the corner's "
         "steel side bar"),
    Case("probe-drogue", "probe-drogue", {"facility.robot_delay": 0.0, "simulation.duration": 3.0},
         "the preset: the capsule probe strikes the drogue mesh (flat prisms in MuJoCo) and slides, "
         "μ_k = 0.2, μ_s = 0.25"),
    Case("probe-drogue mu_s=mu_k", "probe-drogue", {"facility.robot_delay": 0.0, "simulation.duration": 3.0,
                                                    "contact.friction.static": 0.2},
         "the same with μ_s = μ_k = 0.2 (no Stribeck peak)"),
)


@dataclass
class MujocoTrace:
    """What MuJoCo recorded: one row per MuJoCo step (``time``, s), the rod tip's velocity
    relative to the target (``velocity``, ``t``, m/s), the servicer's angular velocity relative
    to the target (``angular_velocity``, ``t``, rad/s), the contact force on the rod per wall
    (``wall_force``, steps × walls × 3, ``t``, N; the force acting during the step after the
    row's time), the moment of the contact forces on the target's frame about the sensor origin
    (``moment``, steps × 3, ``t``, N·m; each force at its contact point), and the matched
    parameters."""

    time: np.ndarray
    velocity: np.ndarray
    angular_velocity: np.ndarray
    wall_force: np.ndarray
    moment: np.ndarray
    matched: MatchedContact
    xml: str
    #: The tangential (friction) part of the shapes' contact force on the rod (steps × 3, ``t``,
    #: N): the friction rows of MuJoCo's contacts between servicer and target shapes.
    shape_friction: np.ndarray | None = None
    #: MuJoCo's active contacts between shapes at each step.
    shape_contacts: np.ndarray | None = None


def relative_tip_motion(qpos_s: np.ndarray, qvel_s: np.ndarray, qpos_t: np.ndarray, qvel_t: np.ndarray,
                        tip: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rod tip's velocity relative to the target and the servicer's angular velocity
    relative to the target, both in ``t`` (as the core's ``RelativeMotion::point_velocity``
    gives them), from two free joints' ``qpos`` (position, quaternion [w, x, y, z]) and ``qvel``
    (world linear velocity, body angular velocity)."""
    r_s, r_t = rotation_matrix(qpos_s[3:7]), rotation_matrix(qpos_t[3:7])
    w_s, w_t = r_s @ qvel_s[3:6], r_t @ qvel_t[3:6]
    arm = r_s @ tip
    tip_world = qpos_s[:3] + arm
    v = qvel_s[:3] + np.cross(w_s, arm) - qvel_t[:3] - np.cross(w_t, tip_world - qpos_t[:3])
    return r_t.T @ v, r_t.T @ (w_s - w_t)


def simulate_mujoco(scenario: Any, timestep: float, duration: float,
                    match: ContactMatch | None = None) -> MujocoTrace:
    """The scene of a resolved scenario (both bodies free, no facility) simulated by MuJoCo for
    ``duration`` s with steps of ``timestep`` s (:func:`hilcontact.mujoco.mjcf.write_mjcf`)."""
    mj = require("the MuJoCo cross-check")
    match = match or ContactMatch()
    xml, matched = write_mjcf(scenario, timestep, match=match)
    m = mj.MjModel.from_xml_string(xml)
    d = mj.MjData(m)
    faces = MeshFaceFilter(mj, m, mesh_faces(scenario)) if match.mesh_faces_only else None
    if faces is not None and not faces.pieces:
        faces = None
    joints = {}
    for body in ("servicer", "target"):
        b = mj.mj_name2id(m, mj.mjtObj.mjOBJ_BODY, body)
        j = m.body_jntadr[b]
        joints[body] = (m.jnt_qposadr[j], m.jnt_dofadr[j])
    for body, config in (("servicer", scenario.servicer), ("target", scenario.target)):
        dof = joints[body][1]
        d.qvel[dof:dof + 3] = config.velocity
        d.qvel[dof + 3:dof + 6] = config.angular_velocity
    tip_geom = mj.mj_name2id(m, mj.mjtObj.mjOBJ_GEOM, "rod-tip")
    walls = {}
    for i, wall in enumerate(scenario.walls):
        walls[mj.mj_name2id(m, mj.mjtObj.mjOBJ_GEOM, wall_geom_name(i, wall.name))] = i
    n_walls = len(scenario.walls)
    shapes_slot = n_walls  # every shape contact (servicer shape against target shape) in one slot
    servicer_body = mj.mj_name2id(m, mj.mjtObj.mjOBJ_BODY, "servicer")
    tip = np.asarray(scenario.rod.tip, dtype=float)
    steps = int(round(duration / timestep))
    time = np.empty(steps + 1)
    velocity = np.empty((steps + 1, 3))
    angular = np.empty((steps + 1, 3))
    force = np.zeros((steps + 1, n_walls + 1, 3))
    moment = np.zeros((steps + 1, 3))
    shape_friction = np.zeros((steps + 1, 3))
    shape_contacts = np.zeros(steps + 1, dtype=int)
    sensor = np.asarray(scenario.facility.sensor_position, dtype=float)
    (qs, vs), (qt, vt) = joints["servicer"], joints["target"]
    f6 = np.zeros(6)
    normal = np.zeros(m.npair)  # each pair's normal force at the last step, N
    slide = np.zeros(m.npair)  # each pair's Σ F_n·s (s the sliding speed) at the last step, N·m/s
    points = np.zeros(m.npair)  # each pair's pushing points at the last step
    per_newton = matched.tracks
    for k in range(steps + 1):
        if k > 0:
            if per_newton:
                # a pair's parameters apply to each of its points: its mean normal force
                speed = np.divide(slide, normal, out=np.zeros_like(slide), where=normal > 0.0)
                mean = np.divide(normal, points, out=np.zeros_like(normal), where=points > 0)
                m.pair_solreffriction[:, 1] = matched.pair_solreffriction(mean, speed)
            if faces is None:
                mj.mj_step(m, d)
            else:
                faces.step(m, d)
        elif faces is None:
            mj.mj_forward(m, d)
        else:
            faces.forward(m, d)
        time[k] = d.time
        velocity[k], angular[k] = relative_tip_motion(d.qpos[qs:qs + 7], d.qvel[vs:vs + 6],
                                                      d.qpos[qt:qt + 7], d.qvel[vt:vt + 6], tip)
        normal[:] = 0.0
        slide[:] = 0.0
        points[:] = 0.0
        if d.ncon:
            r_t = rotation_matrix(d.qpos[qt + 3:qt + 7])
            for i in range(d.ncon):
                c = d.contact[i]
                if c.efc_address < 0 or c.exclude:
                    continue
                mj.mj_contactForce(m, d, i, f6)
                # the force of geom1 on geom2, in the contact frame (rows: normal, tangents)
                on_geom2 = c.frame.reshape(3, 3).T @ f6[:3]
                if c.geom1 == tip_geom and c.geom2 in walls:
                    j, sign = walls[c.geom2], -1.0
                elif c.geom2 == tip_geom and c.geom1 in walls:
                    j, sign = walls[c.geom1], 1.0
                elif m.geom_bodyid[c.geom1] == servicer_body:
                    j, sign = shapes_slot, -1.0
                elif m.geom_bodyid[c.geom2] == servicer_body:
                    j, sign = shapes_slot, 1.0
                else:
                    continue
                on_rod = sign * (r_t.T @ on_geom2)
                force[k, j] += on_rod
                if j == shapes_slot:
                    shape_friction[k] += sign * (r_t.T @ (c.frame.reshape(3, 3)[1:].T @ f6[1:3]))
                    shape_contacts[k] += 1
                point = r_t.T @ (c.pos - d.qpos[qt:qt + 3])
                moment[k] += np.cross(point - sensor, -on_rod)
                pair = _pair_index(m, c)
                normal[pair] += f6[0]
                points[pair] += 1.0
                if c.dim >= 3:
                    a = c.efc_address
                    slide[pair] += f6[0] * math.hypot(d.efc_vel[a + 1], d.efc_vel[a + 2])
    return MujocoTrace(time, velocity, angular, force, moment, matched, xml, shape_friction, shape_contacts)


def _pair_index(m: Any, contact: Any) -> int:
    for j in range(m.npair):
        if {m.pair_geom1[j], m.pair_geom2[j]} == {contact.geom1, contact.geom2}:
            return j
    return 0


@dataclass
class Episode:
    """One contact episode of one engine: start and end, s; the impulse on the rod per wall
    (walls × 3, ``t``, N·s)."""

    start: float
    end: float
    impulse: np.ndarray


def _episodes(time: np.ndarray, force: np.ndarray, dt: float, gap: float) -> list[Episode]:
    """Intervals where some wall pushes (``force``: samples × walls × 3), merged across gaps
    shorter than ``gap`` s; the impulse of sample k is ``force[k]·dt`` (MuJoCo: the force held
    over the step) — the reference's trapezoid is handled by the caller giving mid-step forces."""
    active = np.linalg.norm(force, axis=2).sum(axis=1) > 0.0
    out: list[Episode] = []
    k, n = 0, len(time)
    while k < n:
        if not active[k]:
            k += 1
            continue
        start = k
        while k < n and active[k]:
            k += 1
        end = k
        if out and time[start] - out[-1].end <= gap:
            last = out[-1]
            last.end = time[end - 1] + dt
            last.impulse = last.impulse + force[start:end].sum(axis=0) * dt
        else:
            out.append(Episode(time[start], time[end - 1] + dt, force[start:end].sum(axis=0) * dt))
    return out


def _reference(scenario: Any, period: float) -> Any:
    from ..run import simulate
    from ..scenario import load_scenario

    fine = load_scenario(scenario, {"simulation.period": period, "facility.kind": "model",
                                    "facility.robot_delay": 0.0, "facility.sensor_delay": 0.0})
    return simulate(fine).reference


def _reference_walls(scenario: Any, reference: Any) -> np.ndarray:
    """The reference's contact force split per wall (samples × walls × 3, ``t``), sample-midpoint
    averaged (trapezoid): each wall's share is the force of the law at that wall, which the
    reference's total contact force is the sum of (only the walls the tip penetrates push)."""
    total = reference[["contact_force_x", "contact_force_y", "contact_force_z"]].to_numpy()
    tip = reference[["tip_position_x", "tip_position_y", "tip_position_z"]].to_numpy()
    walls = [(np.asarray(w.point, float), np.asarray(w.normal, float) / np.linalg.norm(w.normal))
             for w in scenario.walls]
    # which walls the tip penetrates; one wall: the whole force is that wall's
    inside = np.stack([((tip - p) @ n) < 0.0 for p, n in walls], axis=1) if walls else np.zeros((len(total), 0), bool)
    force = np.zeros((len(total), len(walls), 3))
    single = inside.sum(axis=1) == 1
    for j in range(len(walls)):
        rows = single & inside[:, j]
        force[rows, j] = total[rows]
    several = inside.sum(axis=1) > 1
    if several.any():
        # several walls at once: the normal parts along each wall's normal, the rest (friction)
        # shared in proportion (exact for perpendicular frictionless walls; see docs/mujoco.md)
        normals = np.stack([n for _, n in walls])
        for k in np.flatnonzero(several):
            js = np.flatnonzero(inside[k])
            nn = normals[js]
            coeffs, *_ = np.linalg.lstsq(nn.T, total[k], rcond=None)
            coeffs = np.maximum(coeffs, 0.0)
            rest = total[k] - nn.T @ coeffs
            share = coeffs / coeffs.sum() if coeffs.sum() > 0 else np.full(len(js), 1.0 / len(js))
            for c, s, j in zip(coeffs, share, js):
                force[k, j] = c * normals[j] + s * rest
    if getattr(scenario.servicer, "shapes", None) or getattr(scenario.target, "shapes", None):
        # shapes as well: the walls' share is the rod tip's (rows where the tip is inside a
        # wall), the rest the shapes' (one slot: the reference's record holds only the total)
        shapes = total - force.sum(axis=1)
        force = np.concatenate([force, shapes[:, None, :]], axis=1)
    else:
        force = np.concatenate([force, np.zeros((len(total), 1, 3))], axis=1)
    mid = np.zeros_like(force)
    mid[:-1] = 0.5 * (force[:-1] + force[1:])
    return mid


def _angular_impulse(time: np.ndarray, moment: np.ndarray, dt: float, episode: Episode) -> np.ndarray:
    """``∫M dt`` over an episode's samples (the moment on the frame about the sensor origin)."""
    rows = (time >= episode.start - 1e-12) & (time < episode.end - 1e-12)
    return moment[rows].sum(axis=0) * dt


def _at(time: np.ndarray, values: np.ndarray, t: float) -> np.ndarray:
    k = int(np.searchsorted(time, t - 1e-12))
    return values[min(k, len(time) - 1)]


def _ratio(a: float, b: float) -> float:
    return a / b if b > 0 else math.nan


def crosscheck(scenario: Any, *, timestep: float | None = None, reference_period: float = 1e-4,
               match: ContactMatch | None = None) -> list[dict[str, Any]]:
    """The cross-check of a resolved scenario: MuJoCo (steps of ``timestep`` s, default the
    scenario's ``facility.mujoco_timestep``) against the ideal reference (sampled every
    ``reference_period`` s), one dict per contact episode matched by order: ``episode``,
    ``start``, ``end``, ``mujoco_start``, ``mujoco_end`` (s), ``velocity_error``,
    ``angular_velocity_error``, ``normal_impulse_error``, ``tangential_impulse_error``,
    ``angular_impulse_error`` (the moment on the frame about the sensor origin, integrated over
    the episode: what turns both bodies) (fractions), ``normal_impulse`` (reference, N·s, per wall touched), ``tangential_impulse``
    (reference, N·s), ``rebound_velocity`` (reference, m/s, ``t``), and ``walls`` (the walls'
    indices that pushed)."""
    timestep = float(scenario.facility.mujoco_timestep if timestep is None else timestep)
    duration = float(scenario.simulation.duration)
    reference = _reference(scenario, reference_period)
    r_time = reference["time"].to_numpy()
    r_force = _reference_walls(scenario, reference)
    r_vel = reference[["tip_velocity_x", "tip_velocity_y", "tip_velocity_z"]].to_numpy()
    r_ang = reference[["angular_velocity_x", "angular_velocity_y", "angular_velocity_z"]].to_numpy()
    r_moment = reference[["contact_moment_x", "contact_moment_y", "contact_moment_z"]].to_numpy()
    r_moment = 0.5 * (r_moment + np.vstack([r_moment[1:], r_moment[-1:]]))  # trapezoid
    mj = simulate_mujoco(scenario, timestep, duration, match)
    gap = 2e-3
    ref_eps = _episodes(r_time, r_force, reference_period, gap)
    mj_eps = _episodes(mj.time, mj.wall_force, timestep, gap)
    normals = [np.asarray(w.normal, float) / np.linalg.norm(w.normal) for w in scenario.walls]
    n_walls = len(scenario.walls)
    r_friction = reference[["friction_force_x", "friction_force_y", "friction_force_z"]].to_numpy()
    if n_walls and (getattr(scenario.servicer, "shapes", None) or getattr(scenario.target, "shapes", None)):
        r_friction = np.zeros_like(r_friction)  # walls and shapes together: the split is the walls' only
    r_friction = 0.5 * (r_friction + np.vstack([r_friction[1:], r_friction[-1:]]))  # trapezoid
    rows = []
    for i, (r, m) in enumerate(zip(ref_eps, mj_eps), start=1):
        t = max(r.end, m.end) + AFTER
        if t > min(r_time[-1], mj.time[-1]):
            break
        v_ref, v_mj = _at(r_time, r_vel, t), _at(mj.time, mj.velocity, t)
        w_ref, w_mj = _at(r_time, r_ang, t), _at(mj.time, mj.angular_velocity, t)
        touched = [j for j in range(n_walls + 1) if np.linalg.norm(r.impulse[j]) > 0 or np.linalg.norm(m.impulse[j]) > 0]
        walls_touched = [j for j in touched if j < n_walls]
        jn_ref = [float(r.impulse[j] @ normals[j]) for j in walls_touched]
        jn_mj = [float(m.impulse[j] @ normals[j]) for j in walls_touched]
        normal_errors = [abs(a - b) / abs(b) for a, b in zip(jn_mj, jn_ref)]
        j_ref, j_mj = r.impulse.sum(axis=0), m.impulse.sum(axis=0)
        jt_ref = sum((r.impulse[j] - (r.impulse[j] @ normals[j]) * normals[j] for j in walls_touched), np.zeros(3))
        jt_mj = sum((m.impulse[j] - (m.impulse[j] @ normals[j]) * normals[j] for j in walls_touched), np.zeros(3))
        if n_walls in touched:
            # the shapes' slot: the normal part is the impulse less its friction part, a vector
            # (the points' normals differ); compared as vectors
            ft_ref = _angular_impulse(r_time, r_friction, reference_period, r)
            ft_mj = _angular_impulse(mj.time, mj.shape_friction, timestep, m)
            sn_ref, sn_mj = r.impulse[n_walls] - ft_ref, m.impulse[n_walls] - ft_mj
            jn_ref.append(float(np.linalg.norm(sn_ref)))
            normal_errors.append(_ratio(float(np.linalg.norm(sn_mj - sn_ref)), float(np.linalg.norm(sn_ref))))
            jt_ref, jt_mj = jt_ref + ft_ref, jt_mj + ft_mj
        h_ref = _angular_impulse(r_time, r_moment, reference_period, r)
        h_mj = _angular_impulse(mj.time, mj.moment, timestep, m)
        rows.append({
            "episode": i,
            "angular_impulse_error": _ratio(float(np.linalg.norm(h_mj - h_ref)), float(np.linalg.norm(h_ref))),
            "start": r.start, "end": r.end, "mujoco_start": m.start, "mujoco_end": m.end,
            "walls": touched,
            "rebound_velocity": v_ref.tolist(),
            "velocity_error": _ratio(float(np.linalg.norm(v_mj - v_ref)), float(np.linalg.norm(v_ref))),
            "angular_velocity_error": float(np.linalg.norm(w_mj - w_ref)) / max(float(np.linalg.norm(w_ref)), OMEGA_FLOOR),
            "angular_velocity": [float(np.linalg.norm(w_ref)), float(np.linalg.norm(w_mj))],
            "normal_impulse": jn_ref,
            "normal_impulse_error": max(normal_errors) if normal_errors else math.nan,
            "tangential_impulse": float(np.linalg.norm(jt_ref)),
            "tangential_impulse_error": _ratio(float(np.linalg.norm(jt_mj - jt_ref)), float(np.linalg.norm(j_ref))),
            "impulse_error": _ratio(float(np.linalg.norm(j_mj - j_ref)), float(np.linalg.norm(j_ref))),
            "episodes": (len(ref_eps), len(mj_eps)),
            "shapes_slot": n_walls,
        })
    return rows


def run_case(case: Case, timestep: float | None = None, match: ContactMatch | None = None) -> list[dict[str, Any]]:
    """:func:`crosscheck` of one :class:`Case`."""
    from dataclasses import replace

    from ..scenario import load_scenario

    match = replace(match or ContactMatch(), **dict(case.match))
    return crosscheck(load_scenario(case.preset, dict(case.overrides)), timestep=timestep, match=match)


def table(cases: tuple[Case, ...] = CASES, timesteps: tuple[float, ...] = (1e-4,),
          match: ContactMatch | None = None, echo: Callable[[str], None] | None = None) -> list[dict[str, Any]]:
    """Every case's episodes at every timestep, one row each (``case``, ``timestep`` and the keys
    of :func:`crosscheck`); ``echo`` gets each row as a line of the Markdown table of
    docs/mujoco.md as it is computed."""
    out = []
    if echo:
        echo("| case | MuJoCo step (s) | episode | episodes ref/MuJoCo | walls | rebound velocity error "
             "| angular velocity error | normal impulse error | tangential impulse error (of \\|J\\|) "
             "| impulse vector error | angular impulse error | \\|J_t\\| ref (N s) |")
        echo("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for case in cases:
        for h in timesteps:
            for row in run_case(case, h, match):
                row = {"case": case.name, "timestep": h, **row}
                out.append(row)
                if echo:
                    walls = ",".join("shapes" if j == row["shapes_slot"] else str(j) for j in row["walls"])
                    echo(f"| {case.name} | {h:g} | {row['episode']} | {row['episodes'][0]}/{row['episodes'][1]} "
                         f"| {walls} | {row['velocity_error']:.3%} | {row['angular_velocity_error']:.3%} "
                         f"| {row['normal_impulse_error']:.3%} | {row['tangential_impulse_error']:.3%} "
                         f"| {row['impulse_error']:.3%} | {row['angular_impulse_error']:.3%} "
                         f"| {row['tangential_impulse']:.4g} |")
    return out
