"""The MJCF writer: a scenario as a MuJoCo model, with MuJoCo's soft contact matched to the
scenario's linear spring-damper and its friction (docs/mujoco.md has the derivation).

The scene:

- two free bodies, ``servicer`` and ``target``, each with its mass, inertia tensor (body frame,
  about the centre of mass: the body frame's origin), initial pose and velocities from the
  scenario (``[servicer]``, ``[target]``; MuJoCo's free joint takes the angular velocity in the
  body frame, as the scenario gives it); no gravity;
- the rod tip: a sphere of radius :attr:`ContactMatch.tip_radius` centred on ``rod.tip`` on the
  servicer;
- each wall: a large thin box fixed on the target whose outer face lies
  :attr:`ContactMatch.tip_radius` behind the wall's plane (so that the sphere's penetration is
  the tip's penetration ``d`` of the scenario's law), facing the wall's normal (MuJoCo's
  ``plane`` geoms can only sit on the world body, and the target floats).

With ``fixed_target`` the target is the world (the mockup frame ``t`` of the facility): the walls
are fixed in the world and the servicer moves as the robot does.

A shape of the lead's ``[[servicer.shapes]]``/``[[target.shapes]]`` tables maps onto one geom
(box, sphere, capsule, cylinder, mesh; a cone as a mesh): :func:`_geom` is where a kind becomes a
geom, with its pose in the body frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any
from xml.sax.saxutils import quoteattr

import numpy as np

from ..errors import ScenarioError

__all__ = ["ContactMatch", "MatchedContact", "inertia_matrix", "rotation_matrix", "rotation_z_to", "wall_geom_name", "write_mjcf"]


@dataclass(frozen=True)
class ContactMatch:
    """How MuJoCo's soft contact is set up to reproduce the scenario's law (docs/mujoco.md,
    "Matching the contact").

    Attributes:
        impedance: MuJoCo's constraint impedance ``d`` (``solimp = d d ...``, constant), 1e-4
            to 0.1: the smaller, the more each contact row is an explicit spring-damper of its
            own (the coupling through the other rows and the free acceleration is of order ``d``).
        tip_radius: radius of the sphere standing for the rod tip, m (the contact point is this
            far from the tip along the normal: a friction force's moment is off by
            ``radius·|F_t|``).
        wall_half_size: half the side of a wall's box, m (a wall is a half-space in the
            scenario; the box must cover every place the tip reaches).
        wall_half_thickness: half the thickness of a wall's box, m.
        impratio: MuJoCo's ``impratio`` (tangential over normal impedance of the elliptic cone):
            large, so that a sliding contact keeps its normal force and the friction is clipped
            to the cone.
        friction_damping: the viscous coefficient of MuJoCo's friction below the cone, N·s/m
            (its sticking) when it is constant (``track_friction`` False); None: ``μ_s·F/v_ε``
            with ``F = v₀·√(k·m_red)``, the peak normal force of a head-on contact at the
            initial relative speed ``v₀``: the slope of the scenario's regularised Coulomb law at
            that force.
        track_friction: the friction's viscous coefficient follows the normal force as the
            scenario's law's slope does, ``μ_s·F_n/v_ε`` with ``F_n`` the pair's normal force of
            the step before (set in ``pair_solreffriction`` each step by the simulation);
            False: constant (``friction_damping``), MuJoCo's own regularisation.
    """

    impedance: float = 1e-4
    tip_radius: float = 1e-4
    wall_half_size: float = 20.0
    wall_half_thickness: float = 0.05
    impratio: float = 100.0
    friction_damping: float | None = None
    track_friction: bool = True


@dataclass(frozen=True)
class MatchedContact:
    """The MuJoCo parameters a :class:`ContactMatch` gives for one scene.

    Attributes:
        diag: MuJoCo's approximate inverse inertia of a contact between the servicer and the
            target, ``body_invweight0`` summed over both bodies, 1/kg (the ``A`` of R = (1−d)/d·A).
        solref: the contact's ``solref``, (−k', −b') (direct stiffness and damping).
        solreffriction: the friction rows' ``solref`` (0, −b'_t).
        friction: the cone's coefficient μ (0: frictionless, ``condim = 1``).
        friction_damping: the friction's viscous coefficient below the cone, N·s/m (the initial
            one with ``track_friction``).
        friction_slope: ``μ_s/v_ε``, s/m: with ``track_friction``, the viscous coefficient is
            this times the normal force.
        solreffriction_per_newton: ``pair_solreffriction[1]`` per newton of normal force with
            ``track_friction`` (negative).
    """

    diag: float
    solref: tuple[float, float]
    solreffriction: tuple[float, float]
    friction: float
    friction_damping: float
    friction_slope: float = 0.0
    solreffriction_per_newton: float = 0.0


def wall_geom_name(index: int, name: str) -> str:
    """The geom name of the scenario's wall ``index`` (named ``name``)."""
    return f"wall{index}" + (f"-{name}" if name else "")


def inertia_matrix(value: Any) -> np.ndarray:
    """A scenario's inertia (principal moments or a 3x3 tensor) as a 3x3 matrix, kg m²."""
    a = np.asarray(value, dtype=float)
    return np.diag(a) if a.shape == (3,) else a.reshape(3, 3)


def rotation_matrix(q: np.ndarray) -> np.ndarray:
    """The rotation matrix of a quaternion [w, x, y, z] (normalised here)."""
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def rotation_z_to(n: np.ndarray) -> np.ndarray:
    """A unit quaternion [w, x, y, z] turning the z axis onto the unit vector ``n``."""
    z = np.array([0.0, 0.0, 1.0])
    n = n / np.linalg.norm(n)
    c = float(z @ n)
    if c < -1.0 + 1e-12:
        return np.array([0.0, 1.0, 0.0, 0.0])
    axis = np.cross(z, n)
    q = np.array([1.0 + c, *axis])
    return q / np.linalg.norm(q)


def _num(values: Any) -> str:
    return " ".join(repr(float(v)) for v in np.ravel(values))


def _body_xml(name: str, body: Any, geoms: list[str], free: bool) -> str:
    inertia = inertia_matrix(body.inertia)
    full = [inertia[0, 0], inertia[1, 1], inertia[2, 2], inertia[0, 1], inertia[0, 2], inertia[1, 2]]
    joint = f'      <freejoint name="{name}-free"/>\n' if free else ""
    return (
        f'    <body name="{name}" pos="{_num(body.position)}" quat="{_num(body.orientation)}">\n'
        f"{joint}"
        f'      <inertial pos="0 0 0" mass="{float(body.mass)!r}" fullinertia="{_num(full)}"/>\n'
        + "".join(geoms)
        + "    </body>\n"
    )


def _geom(name: str, kind: str, size: Any, pos: Any, quat: Any) -> str:
    """One geom: ``kind`` a MuJoCo geom type (sphere, box, capsule, cylinder, mesh), ``size`` its
    MuJoCo size, pose in the body frame. Geoms collide only through the explicit ``<pair>``
    elements of :func:`_document` (``contype = conaffinity = 0``)."""
    return (
        f'      <geom name={quoteattr(name)} type="{kind}" size="{_num(size)}" pos="{_num(pos)}" '
        f'quat="{_num(quat)}" contype="0" conaffinity="0"/>\n'
    )


def _shape_geoms(body: str, shapes: Any) -> list[tuple[str, str]]:
    """The geoms of a body's ``shapes`` (``[[servicer.shapes]]``, ``[[target.shapes]]``): (name,
    XML). Box (full sizes → MuJoCo's half sizes), sphere, capsule (``length`` between the cap
    centres), cylinder (``length`` along z); a shape's ``margin`` (edge rounding) has no MuJoCo
    equivalent: its edges stay sharp. Cones, half-spaces and meshes are not written yet
    (ScenarioError naming the shape)."""
    out = []
    for i, shape in enumerate(shapes or []):
        kind = str(shape.kind)
        name = f"{body}-shape{i}" + (f"-{shape.name}" if shape.name else "")
        if kind == "box":
            size = [0.5 * float(v) for v in shape.size]
        elif kind == "sphere":
            size = [float(shape.radius)]
        elif kind in ("capsule", "cylinder"):
            size = [float(shape.radius), 0.5 * float(shape.length)]
        else:
            raise ScenarioError(f"{body}.shapes[{i}].kind: the MJCF writer has no {kind!r} geom yet (box, sphere, capsule, cylinder)")
        out.append((name, _geom(name, kind, size, shape.position, shape.orientation)))
    return out


def _match(scenario: Any, match: ContactMatch, diag: float) -> MatchedContact:
    c = scenario.contact
    if c.model != "linear":
        raise ScenarioError(
            f"contact.model: MuJoCo's contact can be matched to the linear law only, got {c.model!r} "
            "(docs/mujoco.md, 'Matching the contact')"
        )
    if not 1e-4 <= match.impedance <= 0.1:
        raise ScenarioError(f"impedance: expected 1e-4 to 0.1, got {match.impedance!r}")
    d = match.impedance
    scale = (1.0 - d) * diag
    friction = c.friction
    mu_k = float(friction.kinetic)
    mu_s = float(friction.static) or mu_k
    if match.friction_damping is not None:
        c_t = float(match.friction_damping)
    elif mu_s > 0.0:
        m_red = 1.0 / (1.0 / scenario.servicer.mass + 1.0 / scenario.target.mass)
        v0 = float(np.linalg.norm(np.subtract(scenario.servicer.velocity, scenario.target.velocity)))
        c_t = mu_s * max(v0, 1e-3) * math.sqrt(c.stiffness * m_red) / friction.stick_velocity
    else:
        c_t = 0.0
    slope = mu_s / friction.stick_velocity if mu_s > 0.0 else 0.0
    return MatchedContact(
        diag=diag,
        solref=(-c.stiffness * scale, -c.damping * scale),
        solreffriction=(0.0, -c_t * scale / match.impratio),
        friction=mu_k,
        friction_damping=c_t,
        friction_slope=slope if match.track_friction else 0.0,
        solreffriction_per_newton=-slope * scale / match.impratio if match.track_friction else 0.0,
    )


def _document(scenario: Any, timestep: float, match: ContactMatch, matched: MatchedContact | None,
              fixed_target: bool) -> str:
    d = match.impedance
    if matched is None:  # first pass: only the mass matrix matters
        contact = f'condim="1" solimp="{d!r} {d!r} 0.001 0.5 2"'
    else:
        friction = matched.friction
        condim = 3 if friction > 0.0 else 1
        contact = (
            f'condim="{condim}" friction="{friction!r} {friction!r} 0 0 0" solimp="{d!r} {d!r} 0.001 0.5 2" '
            f'solref="{_num(matched.solref)}" solreffriction="{_num(matched.solreffriction)}" margin="0" gap="0"'
        )
    rho = match.tip_radius
    tip = _geom("rod-tip", "sphere", [rho], scenario.rod.tip, [1, 0, 0, 0])
    walls, pairs = [], []
    for i, wall in enumerate(scenario.walls):
        n = np.asarray(wall.normal, dtype=float)
        n = n / np.linalg.norm(n)
        h = match.wall_half_thickness
        centre = np.asarray(wall.point, dtype=float) - (rho + h) * n
        name = wall_geom_name(i, wall.name)
        walls.append(_geom(name, "box", [match.wall_half_size, match.wall_half_size, h], centre,
                           rotation_z_to(n)))
        pairs.append(f'    <pair geom1="rod-tip" geom2={quoteattr(name)} {contact}/>\n')
    servicer_shapes = _shape_geoms("servicer", getattr(scenario.servicer, "shapes", None))
    target_shapes = _shape_geoms("target", getattr(scenario.target, "shapes", None))
    walls += [xml for _, xml in target_shapes]
    tip += "".join(xml for _, xml in servicer_shapes)
    for a, _ in servicer_shapes:
        for b, _ in target_shapes:
            pairs.append(f'    <pair geom1={quoteattr(a)} geom2={quoteattr(b)} {contact}/>\n')
    servicer = _body_xml("servicer", scenario.servicer, [tip], free=True)
    if fixed_target:
        target = "".join(walls).replace("      <geom", "    <geom")
    else:
        target = _body_xml("target", scenario.target, walls, free=True)
    cone = "elliptic"
    return (
        f"<!-- {scenario.name}: written by hilcontact.mujoco.mjcf from the scenario (docs/mujoco.md) -->\n"
        f'<mujoco model={quoteattr(scenario.name)}>\n'
        '  <compiler angle="radian" autolimits="true"/>\n'
        f'  <option timestep="{timestep!r}" gravity="0 0 0" integrator="Euler" cone="{cone}" '
        f'impratio="{match.impratio!r}" solver="Newton" tolerance="1e-12" iterations="100"/>\n'
        "  <worldbody>\n"
        f"{target}{servicer}"
        "  </worldbody>\n"
        "  <contact>\n"
        f"{''.join(pairs)}"
        "  </contact>\n"
        "</mujoco>\n"
    )


def write_mjcf(scenario: Any, timestep: float = 1e-4, *, match: ContactMatch | None = None,
               fixed_target: bool = False) -> tuple[str, MatchedContact]:
    """The MJCF text of a resolved scenario (:class:`hilcontact.Scenario`) and the contact
    parameters it holds. ``timestep``: MuJoCo's integration step, s. ``fixed_target``: the target
    is the world (the facility's mockup), the servicer free. The model is compiled once to read
    MuJoCo's ``body_invweight0`` (the contact's ``A``), then written with the matched ``solref``.
    Raises ScenarioError for a contact law MuJoCo cannot reproduce (Hunt-Crossley)."""
    import mujoco

    match = match or ContactMatch()
    if not 1e-7 <= timestep <= 1e-2:
        raise ScenarioError(f"facility.mujoco_timestep: expected 1e-7 to 1e-2 s, got {timestep!r}")
    first = mujoco.MjModel.from_xml_string(_document(scenario, timestep, match, None, fixed_target))
    servicer = mujoco.mj_name2id(first, mujoco.mjtObj.mjOBJ_BODY, "servicer")
    target = 0 if fixed_target else mujoco.mj_name2id(first, mujoco.mjtObj.mjOBJ_BODY, "target")
    diag = float(first.body_invweight0[servicer, 0] + first.body_invweight0[target, 0])
    matched = _match(scenario, match, diag)
    return _document(scenario, timestep, match, matched, fixed_target), matched
