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

__all__ = ["ContactMatch", "MatchedContact", "MeshFaceFilter", "mesh_faces", "inertia_matrix", "rotation_matrix", "rotation_z_to", "wall_geom_name", "write_mjcf"]


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
        impratio: MuJoCo's ``impratio`` (tangential over normal impedance of the elliptic cone);
            None: :attr:`cone_impratio`'s default (1 with ``track_sliding``, else 100: large, so
            that a contact clipped to the cone keeps its normal force).
        friction_damping: the viscous coefficient of MuJoCo's friction below the cone, N·s/m
            (its sticking) when it is constant (``track_friction`` False); None: ``μ_s·F/v_ε``
            with ``F = v₀·√(k·m_red)``, the peak normal force of a head-on contact at the
            initial relative speed ``v₀``: the slope of the scenario's regularised Coulomb law at
            that force.
        track_friction: the friction's viscous coefficient follows the normal force as the
            scenario's law's slope does, ``μ_s·F_n/v_ε`` with ``F_n`` the pair's normal force of
            the step before (set in ``pair_solreffriction`` each step by the simulation);
            False: constant (``friction_damping``), MuJoCo's own regularisation.
        track_sliding: with ``track_friction``, the viscous coefficient also follows the pair's
            sliding speed ``s`` of the step before, as the law's secant
            ``μ(s)·F_n/√(s² + v_ε²)``: MuJoCo's friction is then the scenario's regularised
            Coulomb law with its Stribeck curve, and its cone (``max(μ_s, μ_k)``) is never
            reached; False: viscous ``μ_s·F_n/v_ε`` up to the cone ``μ_k·F_n`` (Coulomb beyond).
        round_edges: a box's or cylinder's ``margin`` (our edge rounding) written as a convex
            mesh of the rounded surface (MuJoCo collides it as its hull); False: MuJoCo's sharp
            box and cylinder of the same outer size (a cone is a mesh either way).
        arc_chords: chords per quarter circle of a rounded edge (the chord lies at most
            ``margin·(1 − cos(π/(4·arc_chords)))`` inside the rounded surface: 2.4 µm for 2 mm
            at 16).
        segments: steps around a cylinder's or cone's axis (the chord lies at most
            ``radius·(1 − cos(π/segments))`` inside: 0.75 µm for 10 mm at 256).
        cylinder_primitive: a sharp cylinder (no margin, or ``round_edges`` False) as MuJoCo's
            own cylinder geom; False: a convex mesh of ``segments`` sides (MuJoCo 4.0's
            cylinder-box collision returns the same point twice, along the box face's normal:
            docs/mujoco.md).
        multiccd: MuJoCo's multi-point convex collision (``<flag multiccd>``, on by default in
            MuJoCo): a mesh or box against a mesh or box touches at up to 4 points where their
            faces overlap, the ends of the segment where a hull's facet crosses an edge (two
            points where ours has one, each a full spring); False: one point per pair of geoms
            (box against box keeps MuJoCo's own box-box collision, up to 8 points).
        mesh_faces_only: the core's rule for meshes (docs/model.md, "Shapes"): where a mesh's
            piece touches on its face, the contacts of the same mesh on a piece's edge or corner
            (their normal is not the piece's face normal) are dropped before MuJoCo's solver
            (:func:`mesh_faces`, :func:`drop_mesh_edge_contacts`); False: every touched piece is a
            spring of its own (a probe in a narrow faceted cone touches 4-6 pieces at once).
        mesh_thickness: how deep behind its face each triangle of a mesh surface is extruded
            into a convex prism, m (deeper than any penetration; thinner than what lies behind).
    """

    impedance: float = 1e-4
    tip_radius: float = 1e-4
    wall_half_size: float = 20.0
    wall_half_thickness: float = 0.05
    impratio: float | None = None
    friction_damping: float | None = None
    track_friction: bool = True
    track_sliding: bool = True

    @property
    def cone_impratio(self) -> float:
        """The ``impratio`` written: :attr:`impratio`, or by default 1 when the friction follows
        the sliding speed (inside the cone, the friction rows' regulariser ``R_n/impratio`` then
        dominates the coupling ``A`` as the normal row's does: O(d)), 100 when it does not (the
        cone's projection then moves the friction, not the normal force)."""
        if self.impratio is not None:
            return float(self.impratio)
        return 1.0 if self.track_friction and self.track_sliding else 100.0
    round_edges: bool = True
    arc_chords: int = 16
    segments: int = 256
    mesh_thickness: float = 0.005
    cylinder_primitive: bool = False
    multiccd: bool = False
    mesh_faces_only: bool = True


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
            ``track_friction`` (negative), at rest (times :meth:`sliding_factor` when sliding).
        mu_static, mu_kinetic, stick_velocity, stribeck_velocity: the scenario's friction law
            (``μ_s``, ``μ_k``, ``v_ε`` and ``v_s`` in m/s).
        track_sliding: the viscous coefficient follows the sliding speed too
            (:meth:`sliding_factor`); the cone's ``friction`` is then ``max(μ_s, μ_k)``, never
            reached.
        pair_friction: (μ_k, μ_s) of each ``<pair>`` in the model's order (the walls' pairs,
            then every servicer geom against every target geom): ``[[contact.friction.pairs]]``
            for the two shapes' materials, else ``[contact.friction]``'s.
        friction_gain: ``(1 − d)·Â/impratio`` with ``track_friction`` (0 without): ``b'_t``
            per N·s/m of the friction's viscous coefficient.
    """

    diag: float
    solref: tuple[float, float]
    solreffriction: tuple[float, float]
    friction: float
    friction_damping: float
    friction_slope: float = 0.0
    solreffriction_per_newton: float = 0.0
    mu_static: float = 0.0
    mu_kinetic: float = 0.0
    stick_velocity: float = 1e-3
    stribeck_velocity: float = 5e-3
    track_sliding: bool = False
    pair_friction: tuple[tuple[float, float], ...] = ()
    friction_gain: float = 0.0

    @property
    def tracks(self) -> bool:
        """The simulation sets each pair's ``pair_solreffriction`` every step
        (:meth:`pair_solreffriction`)."""
        return self.friction_gain > 0.0 and any(mu_s > 0.0 for _, mu_s in self.pair_friction)

    def pair_solreffriction(self, normal: Any, speed: Any) -> np.ndarray:
        """Each ``<pair>``'s ``pair_solreffriction[1]`` (``−b'_t``) for its mean normal force per
        point ``normal`` (N) and sliding speed ``speed`` (m/s) of the step before: the pair's
        law's slope at rest ``μ_s,p·F_n/v_ε`` times :meth:`sliding_factor` with the pair's own
        coefficients (:attr:`pair_friction`)."""
        mu = np.asarray(self.pair_friction, dtype=float).reshape(-1, 2)
        slope = mu[:, 1] / self.stick_velocity
        return -self.friction_gain * slope * np.asarray(normal, dtype=float) * self.sliding_factor(speed, mu)

    def sliding_factor(self, speed: Any, mu: Any = None) -> np.ndarray:
        """The friction's viscous coefficient at sliding speed ``speed`` (m/s) over its value at
        rest: ``μ(s)·v_ε / (μ_s·√(s² + v_ε²))`` with ``track_sliding`` (the scenario's law's
        secant: MuJoCo's viscous friction ``c_t·s`` is then the law's force, inside the cone), 1
        without. ``μ(s)`` is the law's Stribeck curve (docs/model.md, "Friction")."""
        s = np.asarray(speed, dtype=float)
        mu_k, mu_s = (self.mu_kinetic, self.mu_static) if mu is None else (np.asarray(mu)[:, 0], np.asarray(mu)[:, 1])
        if not self.track_sliding:
            return np.ones_like(s)
        v_eps, v_s = self.stick_velocity, self.stribeck_velocity
        peak = np.where(np.asarray(mu_s) > 0.0, mu_s, 1.0)
        mu_now = mu_k + (mu_s - mu_k) * np.exp(-(s / v_s) ** 2)
        return np.where(np.asarray(mu_s) > 0.0, mu_now * v_eps / (peak * np.sqrt(s * s + v_eps * v_eps)), 1.0)


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


def _geom(name: str, kind: str, size: Any, pos: Any, quat: Any, mesh: str = "") -> str:
    """One geom: ``kind`` a MuJoCo geom type (sphere, box, capsule, cylinder, plane, mesh: then
    ``mesh`` names its asset), ``size`` its MuJoCo size, pose in the body frame. Geoms collide
    only through the explicit ``<pair>`` elements of :func:`_document` (``contype = conaffinity
    = 0``)."""
    asset = f' mesh={quoteattr(mesh)}' if mesh else ""
    size_attr = f' size="{_num(size)}"' if size is not None else ""
    return (
        f'      <geom name={quoteattr(name)} type="{kind}"{asset}{size_attr} pos="{_num(pos)}" '
        f'quat="{_num(quat)}" contype="0" conaffinity="0"/>\n'
    )


def _mesh_asset(name: str, vertices: np.ndarray) -> str:
    """A mesh asset of ``vertices`` (m, the geom's frame): MuJoCo collides a mesh geom as the
    convex hull of its vertices."""
    return f'    <mesh name={quoteattr(name)} vertex="{_num(vertices)}"/>\n'


def _rounded_box_points(size: Any, margin: float, k: int) -> np.ndarray:
    """Points on the surface of a box of full sizes ``size`` whose core (shrunk by ``margin``) is
    dilated by ``margin`` (the core's shape, docs/model.md "Shapes"): each core corner with a
    ``k × k`` grid of directions over its octant of the sphere (the arcs' chords are at most
    ``margin·(1 − cos(π/(4k)))`` inside the rounded surface)."""
    half = 0.5 * np.asarray(size, dtype=float) - margin
    angles = np.linspace(0.0, 0.5 * math.pi, k + 1)
    octant = np.array([[math.sin(a) * math.cos(b), math.sin(a) * math.sin(b), math.cos(a)]
                       for a in angles for b in angles])
    points = []
    for sx in (-1.0, 1.0):
        for sy in (-1.0, 1.0):
            for sz in (-1.0, 1.0):
                s = np.array([sx, sy, sz])
                points.append(s * half + margin * s * octant)
    return np.unique(np.round(np.concatenate(points), 15), axis=0)


def _revolved_points(profile: list[tuple[float, float]], margin: float, segments: int, k: int) -> np.ndarray:
    """Points on a solid of revolution about z: the convex ``profile`` (ρ, z) corners of its core
    (counter-clockwise, ρ ≥ 0, the axis closing it) dilated by ``margin`` (each corner an arc of
    ``k`` chords over its normals' range), turned about z in ``segments`` steps."""
    poly = [np.array(p, dtype=float) for p in profile]
    full = poly + [np.array([-p[0], p[1]]) for p in reversed(poly) if p[0] > 0.0]  # the mirrored half
    # counter-clockwise order of the full (mirrored) polygon
    centre = np.mean(full, axis=0)
    full.sort(key=lambda p: math.atan2(p[1] - centre[1], p[0] - centre[0]))
    n = len(full)
    outline = []
    for i, p in enumerate(full):
        a, b = full[i - 1], full[(i + 1) % n]
        ea, eb = p - a, b - p
        na = math.atan2(-ea[0], ea[1])  # outward normals (clockwise turn of the edge)
        nb = math.atan2(-eb[0], eb[1])
        while nb < na:
            nb += 2.0 * math.pi
        for t in np.linspace(na, nb, k + 1) if margin > 0.0 else [na]:
            outline.append(p + margin * np.array([math.cos(t), math.sin(t)]))
    outline = [q for q in outline if q[0] >= -1e-15]
    turns = np.linspace(0.0, 2.0 * math.pi, segments, endpoint=False)
    points = [[max(q[0], 0.0) * math.cos(a), max(q[0], 0.0) * math.sin(a), q[1]] for q in outline for a in turns]
    return np.unique(np.round(np.array(points), 15), axis=0)


def _flat_pieces(vertices: np.ndarray, triangles: np.ndarray) -> list[list[int]]:
    """The triangles of a mesh grouped into flat convex pieces: neighbours (sharing an edge) in
    one plane whose union is convex (its area is its convex hull's) are one piece, so that a
    planar quad split into two triangles is one face, as the scenario's law sees it (its edge
    contacts are dropped where a face of the same mesh is within reach: docs/model.md)."""
    normals = np.cross(vertices[triangles[:, 1]] - vertices[triangles[:, 0]],
                       vertices[triangles[:, 2]] - vertices[triangles[:, 0]])
    areas = 0.5 * np.linalg.norm(normals, axis=1)
    unit = normals / (2.0 * areas[:, None])
    scale = float(np.ptp(vertices, axis=0).max()) or 1.0
    by_edge: dict[tuple[int, int], list[int]] = {}
    for i, t in enumerate(triangles):
        for a, b in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0])):
            by_edge.setdefault((min(a, b), max(a, b)), []).append(i)
    groups = [[i] for i in range(len(triangles))]
    owner = list(range(len(triangles)))

    def convex_union(members: list[int]) -> bool:
        n = unit[members[0]]
        points = vertices[np.unique(triangles[members])]
        if np.abs((points - points[0]) @ n).max() > 1e-7 * scale:
            return False
        u = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
        u /= np.linalg.norm(u)
        w = np.cross(n, u)
        flat = np.stack([points @ u, points @ w], axis=1)
        return abs(_hull_area(flat) - areas[members].sum()) <= 1e-6 * areas[members].sum()

    for (a, b), faces in by_edge.items():
        if len(faces) != 2:
            continue
        i, j = owner[faces[0]], owner[faces[1]]
        if i == j or unit[i] @ unit[j] < 1.0 - 1e-10:
            continue
        merged = groups[i] + groups[j]
        if convex_union(merged):
            groups[i] = merged
            for k in groups[j]:
                owner[k] = i
            groups[j] = []
    return [g for g in groups if g]


def _hull_area(points: np.ndarray) -> float:
    """The area of the convex hull of 2-D ``points`` (monotone chain)."""
    pts = sorted(map(tuple, np.round(points, 15)))
    if len(pts) < 3:
        return 0.0

    def cross(o: tuple, a: tuple, b: tuple) -> float:
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower: list[tuple] = []
    upper: list[tuple] = []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    hull = lower[:-1] + upper[:-1]
    return 0.5 * abs(sum(hull[k][0] * hull[k - 1][1] - hull[k - 1][0] * hull[k][1] for k in range(len(hull))))


def _triangle_prisms(vertices: np.ndarray, triangles: np.ndarray, thickness: float) -> list[np.ndarray]:
    """Each flat convex piece of a mesh surface (:func:`_flat_pieces`: a triangle, or coplanar
    neighbours whose union is convex) as a thin convex prism: the piece's vertices and their
    copies ``thickness`` behind it. The piece is the prism's front face; behind a vertex is along
    minus the mean of its triangles' normals (area-weighted), so that neighbouring prisms share
    their side faces (no gap, no overlap along the surface). The front is the side the winding's
    normal (counter-clockwise) points to."""
    normals = np.cross(vertices[triangles[:, 1]] - vertices[triangles[:, 0]],
                       vertices[triangles[:, 2]] - vertices[triangles[:, 0]])  # 2·area·n
    vertex_normal = np.zeros_like(vertices)
    for j in range(3):
        np.add.at(vertex_normal, triangles[:, j], normals)
    vertex_normal /= np.linalg.norm(vertex_normal, axis=1, keepdims=True)
    out = []
    for piece in _flat_pieces(vertices, triangles):
        n = normals[piece[0]] / np.linalg.norm(normals[piece[0]])
        index = np.unique(triangles[piece])
        front = vertices[index]
        behind = vertex_normal[index]
        # the offset behind each vertex, scaled so that the back face is ``thickness`` behind
        depth = thickness / np.maximum(behind @ n, 0.2)
        out.append(np.vstack([front, front - depth[:, None] * behind]))
    return out


def mesh_faces(scenario: Any) -> dict[str, tuple[str, np.ndarray]]:
    """Each mesh piece's geom name → (its mesh's name, the piece's front-face unit normal in its
    body's frame), as :func:`_shape_geoms` names and writes them."""
    out: dict[str, tuple[str, np.ndarray]] = {}
    for body in ("servicer", "target"):
        for i, shape in enumerate(getattr(getattr(scenario, body), "shapes", None) or []):
            if str(shape.kind) != "mesh":
                continue
            name = f"{body}-shape{i}" + (f"-{shape.name}" if shape.name else "")
            vertices = np.asarray(shape.vertices, dtype=float) * float(shape.scale)
            triangles = np.asarray(shape.triangles, dtype=int)
            normals = np.cross(vertices[triangles[:, 1]] - vertices[triangles[:, 0]],
                               vertices[triangles[:, 2]] - vertices[triangles[:, 0]])
            rotation = rotation_matrix(np.asarray(shape.orientation, dtype=float))
            for j, piece in enumerate(_flat_pieces(vertices, triangles)):
                n = normals[piece[0]] / np.linalg.norm(normals[piece[0]])
                out[f"{name}-piece{j}"] = (name, rotation @ n)
    return out


class MeshFaceFilter:
    """The core's rule for mesh contacts in a compiled MuJoCo model (``ContactMatch.mesh_faces_only``):
    :meth:`apply` drops, after MuJoCo's collision, every contact on a mesh piece whose normal is
    not the piece's face normal when a contact of the same mesh is on a face, and rebuilds the
    constraints. ``faces``: :func:`mesh_faces` of the scenario written."""

    #: |cos| above which a contact's normal is its piece's face normal.
    FACE = 1.0 - 1e-6

    def __init__(self, mj: Any, model: Any, faces: dict[str, tuple[str, np.ndarray]]) -> None:
        self._mj = mj
        self.pieces: dict[int, tuple[str, np.ndarray, int]] = {}
        for name, (mesh, normal) in faces.items():
            g = mj.mj_name2id(model, mj.mjtObj.mjOBJ_GEOM, name)
            if g >= 0:
                self.pieces[g] = (mesh, normal, int(model.geom_bodyid[g]))
        #: Contacts dropped so far.
        self.dropped = 0

    def apply(self, model: Any, data: Any) -> None:
        """Drop the edge contacts of ``data`` (after ``mj_fwdPosition``) and rebuild the
        constraints (``mj_makeConstraint``, ``mj_island``, ``mj_projectConstraint``)."""
        if not self.pieces or not data.ncon:
            return
        face_meshes = set()
        edges = []
        for i in range(data.ncon):
            c = data.contact[i]
            g = c.geom1 if c.geom1 in self.pieces else c.geom2 if c.geom2 in self.pieces else -1
            if g < 0 or c.exclude:
                continue
            mesh, normal, body = self.pieces[g]
            n = data.xmat[body].reshape(3, 3) @ normal
            if abs(float(c.frame[:3] @ n)) > self.FACE:
                face_meshes.add(mesh)
            else:
                edges.append((i, mesh))
        drop = [i for i, mesh in edges if mesh in face_meshes]
        if not drop:
            return
        for i in drop:
            data.contact[i].exclude = 1
        self.dropped += len(drop)
        mj = self._mj
        mj.mj_makeConstraint(model, data)
        mj.mj_island(model, data)
        mj.mj_projectConstraint(model, data)

    def forward(self, model: Any, data: Any) -> None:
        """``mj_forward`` with the rule: the position stage, the drop, the rest."""
        mj = self._mj
        mj.mj_fwdPosition(model, data)
        self.apply(model, data)
        mj.mj_forwardSkip(model, data, mj.mjtStage.mjSTAGE_POS, 0)

    def step(self, model: Any, data: Any) -> None:
        """``mj_step`` (Euler) with the rule."""
        self.forward(model, data)
        self._mj.mj_Euler(model, data)


def _shape_geoms(body: str, shapes: Any, match: ContactMatch, static: bool) -> tuple[list[tuple[str, str, str]], list[str]]:
    """The geoms of a body's ``shapes`` (``[[servicer.shapes]]``, ``[[target.shapes]]``): (name,
    XML, the shape's material) per geom and the mesh assets they use (docs/mujoco.md, "Shapes in MJCF"):

    - sphere, capsule (``length`` between the cap centres): MuJoCo's own, rounded as ours;
    - box, cylinder: with a ``margin`` and ``match.round_edges``, a convex mesh of points on the
      rounded surface (the core dilated by the margin, :func:`_rounded_box_points`,
      :func:`_revolved_points`); else MuJoCo's sharp box of the stated outer size, and a sharp
      cylinder as a convex mesh (MuJoCo's own with ``match.cylinder_primitive``);
    - cone (base at −length/2, apex at +length/2): always a convex mesh (MuJoCo has no cone),
      rounded as the box;
    - half-space: a ``plane`` geom when the body is ``static`` (MuJoCo's planes are half-spaces
      along their +z, only on static bodies), else a large thin box whose +z face is the plane
      (:attr:`ContactMatch.wall_half_size`, :attr:`ContactMatch.wall_half_thickness`);
    - mesh (a surface): one convex prism per flat convex piece (a triangle, or coplanar
      neighbours whose union is convex), ``match.mesh_thickness`` deep behind the face its
      winding's normal faces (:func:`_triangle_prisms`), named ``<shape>-piece<j>``."""
    geoms: list[tuple[str, str, str]] = []
    assets: list[str] = []
    for i, shape in enumerate(shapes or []):
        kind = str(shape.kind)
        first = len(geoms)
        name = f"{body}-shape{i}" + (f"-{shape.name}" if shape.name else "")
        pos, quat = shape.position, shape.orientation
        margin = float(shape.margin) if match.round_edges else 0.0
        if kind == "sphere":
            geoms.append((name, _geom(name, "sphere", [float(shape.radius)], pos, quat)))
        elif kind == "capsule":
            geoms.append((name, _geom(name, "capsule", [float(shape.radius), 0.5 * float(shape.length)], pos, quat)))
        elif kind == "box" and margin <= 0.0:
            geoms.append((name, _geom(name, "box", [0.5 * float(v) for v in shape.size], pos, quat)))
        elif kind == "cylinder" and margin <= 0.0 and match.cylinder_primitive:
            geoms.append((name, _geom(name, "cylinder", [float(shape.radius), 0.5 * float(shape.length)], pos, quat)))
        elif kind in ("box", "cylinder", "cone"):
            r, h = float(shape.radius) - margin, 0.5 * float(shape.length) - margin
            if kind == "box":
                points = _rounded_box_points(shape.size, margin, match.arc_chords)
            elif kind == "cylinder":
                points = _revolved_points([(r, -h), (r, h)], margin, match.segments, match.arc_chords)
            else:
                points = _revolved_points([(r, -h), (0.0, h)], margin, match.segments, match.arc_chords)
            assets.append(_mesh_asset(name, points))
            geoms.append((name, _geom(name, "mesh", None, pos, quat, mesh=name)))
        elif kind == "half-space":
            n = np.asarray(shape.normal, dtype=float)
            n = n / np.linalg.norm(n)
            if static:
                geoms.append((name, _geom(name, "plane", [0, 0, 1], pos, rotation_z_to(n))))
            else:
                t = match.wall_half_thickness
                centre = np.asarray(pos, dtype=float) - t * n
                geoms.append((name, _geom(name, "box", [match.wall_half_size, match.wall_half_size, t], centre, rotation_z_to(n))))
        elif kind == "mesh":
            vertices = np.asarray(shape.vertices, dtype=float) * float(shape.scale)
            triangles = np.asarray(shape.triangles, dtype=int)
            for j, prism in enumerate(_triangle_prisms(vertices, triangles, match.mesh_thickness)):
                piece = f"{name}-piece{j}"
                assets.append(_mesh_asset(piece, prism))
                geoms.append((piece, _geom(piece, "mesh", None, pos, quat, mesh=piece)))
        else:
            raise ScenarioError(f"{body}.shapes[{i}].kind: the MJCF writer has no {kind!r} geom")
        geoms[first:] = [(g, xml, str(shape.material)) for g, xml, *_ in geoms[first:]]
    return geoms, assets


def pair_coefficients(scenario: Any, material_a: str, material_b: str) -> tuple[float, float]:
    """(μ_k, μ_s) of a contact between shapes of materials ``material_a`` and ``material_b``:
    the ``[[contact.friction.pairs]]`` entry naming both (either order), else
    ``[contact.friction]``'s; ``μ_s`` 0 means ``μ_k`` (docs/scenario.md)."""
    friction = scenario.contact.friction
    for pair in getattr(friction, "pairs", None) or []:
        a, b = (str(x) for x in pair.materials)
        if {a, b} == {material_a, material_b} and (a == b) == (material_a == material_b):
            mu_k = float(pair.kinetic)
            return mu_k, float(pair.static) or mu_k
    mu_k = float(friction.kinetic)
    return mu_k, float(friction.static) or mu_k


def _match(scenario: Any, match: ContactMatch, diag: float,
           pair_friction: tuple[tuple[float, float], ...] = ()) -> MatchedContact:
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
    any_friction = mu_s > 0.0 or any(p_s > 0.0 for _, p_s in pair_friction)
    sliding = match.track_friction and match.track_sliding and any_friction
    return MatchedContact(
        diag=diag,
        solref=(-c.stiffness * scale, -c.damping * scale),
        solreffriction=(0.0, -c_t * scale / match.cone_impratio),
        friction=max(mu_k, mu_s) if sliding else mu_k,
        mu_static=mu_s,
        mu_kinetic=mu_k,
        stick_velocity=float(friction.stick_velocity),
        stribeck_velocity=float(friction.stribeck_velocity),
        track_sliding=sliding,
        friction_damping=c_t,
        friction_slope=slope if match.track_friction else 0.0,
        solreffriction_per_newton=-slope * scale / match.cone_impratio if match.track_friction else 0.0,
        pair_friction=tuple(pair_friction),
        friction_gain=scale / match.cone_impratio if match.track_friction else 0.0,
    )


def _document(scenario: Any, timestep: float, match: ContactMatch, matched: MatchedContact | None,
              fixed_target: bool) -> str:
    d = match.impedance

    def contact(index: int) -> str:
        if matched is None:  # first pass: only the mass matrix matters
            return f'condim="1" solimp="{d!r} {d!r} 0.001 0.5 2"'
        mu_k, mu_s = matched.pair_friction[index]
        friction = max(mu_k, mu_s) if matched.track_sliding else mu_k
        condim = 3 if friction > 0.0 else 1
        # the pair's viscous coefficient at rest before the first step (the simulation then sets
        # it every step): the table's, scaled to the pair's μ_s
        ratio = mu_s / matched.mu_static if matched.mu_static > 0.0 else 0.0
        b_t = matched.solreffriction[1] * ratio if matched.mu_static > 0.0 else matched.solreffriction[1]
        return (
            f'condim="{condim}" friction="{friction!r} {friction!r} 0 0 0" solimp="{d!r} {d!r} 0.001 0.5 2" '
            f'solref="{_num(matched.solref)}" solreffriction="{_num((0.0, b_t))}" margin="0" gap="0"'
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
        pairs.append(f'    <pair geom1="rod-tip" geom2={quoteattr(name)} {contact(len(pairs))}/>\n')
    servicer_shapes, servicer_assets = _shape_geoms("servicer", getattr(scenario.servicer, "shapes", None), match, False)
    target_shapes, target_assets = _shape_geoms("target", getattr(scenario.target, "shapes", None), match, fixed_target)
    assets = servicer_assets + target_assets
    asset = f"  <asset>\n{''.join(assets)}  </asset>\n" if assets else ""
    walls += [xml for _, xml, _ in target_shapes]
    tip += "".join(xml for _, xml, _ in servicer_shapes)
    for a, _, _ in servicer_shapes:
        for b, _, _ in target_shapes:
            pairs.append(f'    <pair geom1={quoteattr(a)} geom2={quoteattr(b)} {contact(len(pairs))}/>\n')
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
        f'impratio="{match.cone_impratio!r}" solver="Newton" tolerance="1e-12" iterations="100">\n'
        f'    <flag multiccd="{"enable" if match.multiccd else "disable"}"/>\n'
        "  </option>\n"
        f"{asset}"
        "  <worldbody>\n"
        f"{target}{servicer}"
        "  </worldbody>\n"
        "  <contact>\n"
        f"{''.join(pairs)}"
        "  </contact>\n"
        "</mujoco>\n"
    )


def _pair_friction(scenario: Any, match: ContactMatch, fixed_target: bool) -> tuple[tuple[float, float], ...]:
    """(μ_k, μ_s) of every ``<pair>`` in the order :func:`_document` writes them: the rod tip on
    each wall (``[contact.friction]``), then every servicer geom on every target geom (their
    shapes' materials, :func:`pair_coefficients`)."""
    table = pair_coefficients(scenario, "\0", "\0")  # no shape has a NUL material: the table's
    out = [table] * len(scenario.walls)
    servicer, _ = _shape_geoms("servicer", getattr(scenario.servicer, "shapes", None), match, False)
    target, _ = _shape_geoms("target", getattr(scenario.target, "shapes", None), match, fixed_target)
    for _, _, a in servicer:
        for _, _, b in target:
            out.append(pair_coefficients(scenario, a, b))
    return tuple(out)


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
    matched = _match(scenario, match, diag, _pair_friction(scenario, match, fixed_target))
    return _document(scenario, timestep, match, matched, fixed_target), matched
