"""Binary PLY point clouds (x, y, z in mm, camera frame, plus an integer stripe index), readable by
Open3D, CloudCompare and MeshLab."""

from __future__ import annotations

import numpy as np


def write_ply(points: np.ndarray, stripe: np.ndarray | None = None) -> bytes:
    """Encode points (N, 3) mm and optional stripe indices (N,) as binary little-endian PLY."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    if stripe is not None:
        fields.append(("stripe", "<i4"))
    rec = np.empty(len(pts), dtype=fields)
    rec["x"], rec["y"], rec["z"] = pts[:, 0], pts[:, 1], pts[:, 2]
    if stripe is not None:
        rec["stripe"] = np.asarray(stripe).reshape(-1)
    props = "".join(f"property {'float' if t == '<f4' else 'int'} {n}\n" for n, t in fields)
    head = f"ply\nformat binary_little_endian 1.0\ncomment bodyscan, mm, camera frame\nelement vertex {len(pts)}\n{props}end_header\n"
    return head.encode("ascii") + rec.tobytes()


def read_ply(data: bytes) -> dict[str, np.ndarray]:
    """Decode a PLY written by write_ply (binary little-endian vertex list): {property name: array}."""
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode("ascii").splitlines()
    count = next(int(h.split()[-1]) for h in header if h.startswith("element vertex"))
    types = {"float": "<f4", "double": "<f8", "int": "<i4", "uchar": "u1"}
    fields = [(h.split()[2], types[h.split()[1]]) for h in header if h.startswith("property")]
    rec = np.frombuffer(data[end:], dtype=fields, count=count)
    return {name: rec[name].copy() for name, _ in fields}
