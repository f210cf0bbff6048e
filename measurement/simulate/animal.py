"""A procedural quadruped with known anatomy (torso, neck, head, legs, tail), or any mesh scaled to size.

Animal frame: x forward (toward the head), y up, z lateral; the feet stand on the floor y = 0; mm.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import trimesh


@dataclass(frozen=True, eq=False)
class Animal:
    """An animal mesh in its own frame plus anatomical truths in the same frame (mm).

    vertices : (V, 3) float64; faces : (F, 3) int64
    anatomy  : JSON-ready dict; polylines and landmarks are lists of [x, y, z]
    """

    vertices: np.ndarray
    faces: np.ndarray
    anatomy: dict = field(default_factory=dict)


def _ellipsoid(centre, axes, subdiv: int = 4) -> trimesh.Trimesh:
    m = trimesh.creation.icosphere(subdivisions=subdiv)
    m.vertices = m.vertices * np.asarray(axes) + np.asarray(centre)
    return m


def _tube(path: np.ndarray, radii: np.ndarray, sides: int = 20) -> trimesh.Trimesh:
    """A closed tube along ``path`` (P, 3) with radius ``radii`` (P,) at each point, capped at both ends."""
    tang = np.gradient(path, axis=0)
    tang /= np.linalg.norm(tang, axis=1, keepdims=True)
    ref = np.array([0.0, 0.0, 1.0]) if abs(tang[0, 2]) < 0.9 else np.array([0.0, 1.0, 0.0])
    rings = []
    u = np.cross(tang[0], ref)
    u /= np.linalg.norm(u)
    ang = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    for p, t, r in zip(path, tang, radii, strict=True):
        u = u - t * (u @ t)  # parallel transport of the ring frame
        u /= np.linalg.norm(u)
        v = np.cross(t, u)
        rings.append(p + r * (np.cos(ang)[:, None] * u + np.sin(ang)[:, None] * v))
    verts = np.vstack(rings + [path[:1], path[-1:]])
    faces = []
    n = len(path)
    for i in range(n - 1):
        a, b = i * sides, (i + 1) * sides
        for j in range(sides):
            k = (j + 1) % sides
            faces += [[a + j, b + j, b + k], [a + j, b + k, a + k]]
    c0, c1 = n * sides, n * sides + 1
    for j in range(sides):
        k = (j + 1) % sides
        faces += [[c0, k, j], [c1, (n - 1) * sides + j, (n - 1) * sides + k]]
    return trimesh.Trimesh(verts, np.array(faces), process=False)


def _capsule(p0, p1, radius: float) -> trimesh.Trimesh:
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    length = float(np.linalg.norm(p1 - p0))
    m = trimesh.creation.capsule(height=length, radius=radius, count=[24, 24])
    m.apply_translation([0, 0, -m.vertices[:, 2].min() - radius])  # cap centres at z = 0 and z = length
    z = (p1 - p0) / length
    m.apply_transform(trimesh.geometry.align_vectors([0, 0, 1], z))
    m.apply_translation(p0)
    return m


def quadruped(length_mm: float = 300.0, seed: int = 0) -> Animal:
    """A fox/dog-sized quadruped whose torso is ``length_mm`` long, with slightly random proportions."""
    rng = np.random.default_rng(seed)
    s = length_mm / 420.0
    j = lambda v, f=0.04: v * (1 + rng.uniform(-f, f))  # noqa: E731  small proportion jitter
    torso_a, torso_b, torso_c = 210 * s, j(105 * s), j(85 * s)
    leg_len = j(300 * s)
    cy = leg_len + 0.1 * torso_b
    parts = [_ellipsoid([0, cy, 0], [torso_a, torso_b, torso_c])]
    neck_r = j(44 * s)
    neck0 = np.array([0.78 * torso_a, cy + 0.35 * torso_b, 0])
    neck1 = neck0 + np.array([95 * s, 100 * s, 0])
    parts.append(_capsule(neck0, neck1, neck_r))
    head_c = neck1 + np.array([35 * s, 15 * s, 0])
    parts.append(_ellipsoid(head_c, [j(80 * s), j(52 * s), j(48 * s)], 3))
    parts.append(_ellipsoid(head_c + [85 * s, -22 * s, 0], [55 * s, 28 * s, 28 * s], 3))
    leg_r = j(27 * s)
    for lx in (0.66 * torso_a, -0.66 * torso_a):
        for lz in (0.55 * torso_c, -0.55 * torso_c):
            parts.append(_capsule([lx, cy - 0.3 * torso_b, lz], [lx, leg_r, lz], leg_r))
    t = np.linspace(0, 1, 24)
    tail = np.column_stack([
        -0.93 * torso_a - 230 * s * t,
        cy + 0.25 * torso_b - 170 * s * t**1.5 + 25 * s * np.sin(np.pi * t),
        35 * s * t**2,
    ])
    tail_r = (22 - 14 * t) * s
    parts.append(_tube(tail, tail_r))
    mesh: trimesh.Trimesh = trimesh.util.concatenate(parts)  # type: ignore[assignment]
    neck_mid = (neck0 + neck1) / 2
    axis = (neck1 - neck0) / np.linalg.norm(neck1 - neck0)
    up = np.array([-axis[1], axis[0], 0.0])
    anatomy = {
        "species": "procedural quadruped",
        "torso_length_mm": float(2 * torso_a),
        "torso_height_mm": float(2 * torso_b),
        "torso_width_mm": float(2 * torso_c),
        "withers_height_mm": float(cy + torso_b),
        "tail_centreline": tail.tolist(),
        "tail_radius_mm": tail_r.tolist(),
        "tail_length_mm": float(np.linalg.norm(np.diff(tail, axis=0), axis=1).sum()),
        "neck_centre": neck_mid.tolist(),
        "neck_axis": axis.tolist(),
        "neck_up": up.tolist(),
        "neck_radius_mm": float(neck_r),
    }
    return Animal(np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64), anatomy)


def from_mesh(path: str, length_mm: float = 600.0) -> Animal:
    """Any trimesh-loadable mesh, scaled so its longest horizontal extent is ``length_mm``, feet on y = 0.

    Axes by extent: the longest becomes the body axis (x), the middle one up (y), the shortest the
    width (z) -- length > height > width holds for the shared quadrupeds whichever axis their file
    calls up (y-up OBJ exports, the z-up horse). The up axis keeps its file sign."""
    loaded: trimesh.Trimesh = trimesh.load(path, force="mesh")  # type: ignore[assignment]
    v = np.asarray(loaded.vertices, dtype=np.float64)
    ext = v.max(axis=0) - v.min(axis=0)
    long_, up, short = int(np.argmax(ext)), int(np.argsort(ext)[1]), int(np.argmin(ext))
    rot = np.zeros((3, 3))
    rot[0, long_], rot[1, up], rot[2, short] = 1.0, 1.0, 1.0
    rot[2] *= np.linalg.det(rot)  # a rotation, not a mirror
    v = v @ rot.T
    ext = v.max(axis=0) - v.min(axis=0)
    v = (v - [(v[:, 0].max() + v[:, 0].min()) / 2, v[:, 1].min(), (v[:, 2].max() + v[:, 2].min()) / 2])
    v *= length_mm / ext[0]
    faces = np.asarray(loaded.faces, np.int64)
    return Animal(v, faces, {"species": f"mesh {path}", "mesh_length_mm": float(length_mm),
                             "mesh_height_mm": float(v[:, 1].max())})
