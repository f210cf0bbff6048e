"""Write a simulated capture folder (the project's import format) with its ground truth beside it.

    OUT/rig.json                 {"board_cols", "board_rows", "square_mm", "stripes"[, "camera_gamma"]}
    OUT/calib/pose_NN_board.png  room light only          OUT/calib/pose_NN_stripes.png  stripes on
    OUT/scan/<view>.png          animal under stripes     OUT/scan/<view>_ambient.png    stripes off
    OUT/truth/truth.json         intrinsics, planes, board poses
    OUT/truth/<view>.json        anatomy in camera coordinates, scene transform
    OUT/truth/<view>_stripes.npz exact lit stripe points (points, stripe, uv, kind)
    OUT/truth/<view>_animal.ply  the animal surface in camera coordinates
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import trimesh

from ..camera import ray_grid
from ..orientation import swap_xy, transpose_image
from .animal import Animal, from_mesh, quadruped
from .boards import Board, board_surface, sample_poses
from .render import Lighting, expose, stripe_irradiance, stripe_truth
from .rig import Rig, default_rig
from .scene import MeshSurface, PlaneSurface, trace

VIEW_CAMERAS = {  # camera centre and look-at target in the world frame (Y up, animal along X, floor Y = 0)
    "side": ((-30.0, 480.0, -1250.0), (-30.0, 230.0, 0.0), (0.0, 1.0, 0.0)),
    "top": ((-30.0, 1350.0, 0.0), (-30.0, 0.0, 0.0), (0.0, 0.0, -1.0)),
    "front": ((1150.0, 420.0, 0.0), (0.0, 220.0, 0.0), (0.0, 1.0, 0.0)),
    "back": ((-1150.0, 420.0, 0.0), (0.0, 220.0, 0.0), (0.0, 1.0, 0.0)),
}
WALLS = {"side": ((0, 0, 1), 380.0), "front": ((-1, 0, 0), 650.0), "back": ((1, 0, 0), 650.0)}


def look_at(centre, target, up) -> tuple[np.ndarray, np.ndarray]:
    """R_cam_world, t_cam_world of an OpenCV camera (x right, y down, z forward) at ``centre``."""
    c, z = np.asarray(centre, float), np.asarray(target, float) - np.asarray(centre, float)
    z /= np.linalg.norm(z)
    down = -np.asarray(up, float)
    y = down - z * (down @ z)
    y /= np.linalg.norm(y)
    x = np.cross(y, z)
    R = np.vstack([x, y, z])
    return R, -R @ c


def _noise3(points: np.ndarray, rng_seed: int, waves: int = 7, lo: float = 50, hi: float = 220) -> np.ndarray:
    """Smooth 3-D value field in [-1, 1] from random plane waves (wavelengths lo..hi mm)."""
    rng = np.random.default_rng(rng_seed)
    out = np.zeros(len(points))
    for _ in range(waves):
        k = rng.standard_normal(3)
        k *= 2 * np.pi / rng.uniform(lo, hi) / np.linalg.norm(k)
        out += np.sin(points @ k + rng.uniform(0, 2 * np.pi))
    return out / np.sqrt(waves / 2)


FLOORS = ("mottled", "concrete", "tiles")


def animal_scene(animal: Animal, view: str, fur: bool, seed: int, wall: bool = True,
                 floor_albedo: float | None = None, floor: str = "mottled",
                 box: tuple[float, float] | None = None, coat: float = 1.0,
                 platform: float | None = None, rails: float | None = None,
                 camera_height: float = 0.0, camera_aimed: bool = False, camera_back: float = 0.0
                 ) -> tuple[list, np.ndarray, np.ndarray]:
    """Surfaces of a scan scene in camera coordinates plus the camera pose (R_cam_world, t_cam_world).
    ``wall`` : the view's wall, if it has one; ``floor_albedo`` : a uniform floor instead of the mottled one;
    ``floor`` : the floor's pattern: "mottled" (slow blotches), "concrete" (the blotches plus a fine-grained
    speckle, 8-80 mm) or "tiles" (150 mm tiles, their 6 mm dark grout lines along the world x and z axes:
    in a top view the lines across the body run along the stripes); ``box`` : (x, z) world mm of the centre
    of a feed box on the floor, 260 x 180 x 220 mm (x, height, z), kind "background"; ``coat`` scales the
    animal's albedo (0.25: a black coat, 0.03-0.22 with fur); ``platform`` : the animal stands on a weighing
    platform this many mm high (900 x 450 mm, kind "background"), its front parallel to the side view's wall;
    ``rails`` : the world z (mm) of two rails of a chute, 40 x 40 x 1400 mm along the animal at heights 150
    and 400 mm (kind "background"; -300 puts them between the animal and the side camera); ``camera_height``
    : mm added to the camera's height (the projector moves with it): a side, front or back camera keeps its
    viewing direction (its target moves too) unless ``camera_aimed`` (then it tilts to keep the animal
    centred); the top camera's distance to the floor changes by as much. ``camera_back`` : mm the camera (and
    projector) steps back along its viewing direction, away from the animal (negative: nearer)."""
    if floor not in FLOORS:
        raise ValueError(f"floor must be one of {', '.join(FLOORS)}, got {floor!r}")
    centre, target, up = (np.asarray(v, float) for v in VIEW_CAMERAS[view])
    up_by = np.array([0.0, camera_height, 0.0])
    if camera_back:
        centre = centre + camera_back * (centre - target) / np.linalg.norm(centre - target)
    R, t = look_at(centre + up_by, target if view == "top" or camera_aimed else target + up_by, up)
    to_world = lambda p: (p - t) @ R  # noqa: E731  camera -> world

    def fur_albedo(points: np.ndarray) -> np.ndarray:
        if not fur:
            return np.full(len(points), 0.62 * coat)
        n = _noise3(to_world(points), seed + 11)
        return np.clip(0.5 + 0.32 * n, 0.12, 0.9) * coat

    def floor_pattern(points: np.ndarray) -> np.ndarray:
        if floor_albedo is not None:
            return np.full(len(points), floor_albedo)
        world = to_world(points)
        out = 0.38 + 0.08 * _noise3(world, seed + 5, 5, 80, 400)
        if floor == "concrete":
            out += 0.06 * _noise3(world, seed + 105, 60, 8, 80)
        elif floor == "tiles":
            grout = np.zeros(len(points), bool)
            for axis in (0, 2):
                grout |= np.abs(np.mod(world[:, axis], 150.0) - 75.0) > 72.0
            out[grout] = 0.1
        return np.clip(out, 0.02, 1.0)

    lift = np.array([0.0, platform or 0.0, 0.0])
    surfaces: list = [MeshSurface((animal.vertices + lift) @ R.T + t, animal.faces, "animal", fur_albedo)]
    n_floor = R @ np.array([0.0, 1.0, 0.0])
    surfaces.append(PlaneSurface(n_floor, float(n_floor @ t), "floor", floor_pattern))
    if wall and view in WALLS:
        nw, off = WALLS[view]
        n_wall = R @ np.asarray(nw, float)
        surfaces.append(PlaneSurface(n_wall, float(off + n_wall @ t), "wall",
                                     lambda p: 0.58 + 0.04 * _noise3(to_world(p), seed + 7, 4, 200, 800)))
    if platform:
        surfaces.append(_block((900.0, platform, 450.0), (-30.0, platform / 2, 0.0), 0.45, R, t))
    if rails is not None:
        surfaces += [_block((1400.0, 40.0, 40.0), (-30.0, height, rails), 0.5, R, t) for height in (150.0, 400.0)]
    if box is not None:
        surfaces.append(_block((260.0, 180.0, 220.0), (box[0], 90.0, box[1]), 0.5, R, t))
    return surfaces, R, t


def _block(size: tuple[float, float, float], centre: tuple[float, float, float], albedo: float,
           R: np.ndarray, t: np.ndarray) -> MeshSurface:
    """An axis-aligned box of ``size`` (x, y, z) mm centred at ``centre`` (world mm), uniform ``albedo``, in
    camera coordinates (kind "background": a platform, a rail, a feed box)."""
    mesh = trimesh.creation.box(size)
    v = mesh.vertices + np.asarray(centre)
    return MeshSurface(v @ R.T + t, np.asarray(mesh.faces), "background", lambda p: np.full(len(p), albedo))


def calibration_scene(board: Board, R: np.ndarray, t: np.ndarray, fx: float) -> list:
    """The plate in front of a dim far wall."""
    far = PlaneSurface(np.array([0.0, 0.0, 1.0]), 3200.0, "background", lambda p: np.full(len(p), 0.3))
    return [board_surface(board, R, t, fx), far]


def write_capture(out_dir: str | Path, stripes: int = 40, size: tuple[int, int] = (3072, 2048), seed: int = 0,
                  scenes: tuple[str, ...] = ("side", "top"), poses: int = 12, mesh: str | None = None,
                  fur: bool = True, board: Board | None = None, defects: dict[int, str] | None = None,
                  rig: Rig | None = None, light: dict | None = None, scene: dict | None = None,
                  gamma: float = 1.0, mesh_length_mm: float = 600.0) -> Path:
    """Render a complete capture (calibration poses + animal views) with ground truth; returns ``out_dir``.

    defects : {pose number (1-based): "no_board" | "no_stripes"} renders deliberately unusable poses.
    light   : overrides of Lighting fields for every exposure (e.g. {"read_noise": 4.0, "gain": 0.8}),
              plus "stripe_ambient" to set the room light of the calibration stripe images.
    scene   : options of the animal views' scene (``animal_scene``: "wall", "floor_albedo", "floor", "box",
              "coat", "platform", "rails", "camera_height", "camera_aimed", "camera_back").
    gamma   : the camera's display gamma: every image is written encoded with it (``display_encoded``: 2.2 as
              an sRGB camera or renderer writes), and rig.json and truth.json say so (``camera_gamma``)
    mesh_length_mm : the longest horizontal extent ``mesh`` is scaled to (``animal.from_mesh``)
    """
    light = dict(light or {})
    stripe_ambient = light.pop("stripe_ambient", None)
    out = Path(out_dir)
    for view in scenes:
        if view not in VIEW_CAMERAS:
            raise ValueError(f"scene {view!r} unknown; choose from {', '.join(VIEW_CAMERAS)}")
    for sub in ("calib", "scan", "truth"):
        (out / sub).mkdir(parents=True, exist_ok=True)
    board = board or Board()
    rig = rig or default_rig(size, stripes)
    rng = np.random.default_rng(seed)
    rays_xy = ray_grid(rig.intrinsics)
    settings = {"board_cols": board.cols, "board_rows": board.rows, "square_mm": board.square_mm, "stripes": stripes}
    (out / "rig.json").write_text(json.dumps({**settings, "camera_gamma": gamma} if gamma != 1.0 else settings))
    truth = _rig_truth(rig, board)
    if gamma != 1.0:
        truth["camera_gamma"] = gamma

    def write(path: Path, img: np.ndarray) -> None:
        cv2.imwrite(str(path), display_encoded(img, gamma))

    defects = defects or {}
    for i, (R, t) in enumerate(sample_poses(board, rig, poses, rng), start=1):
        name = f"pose_{i:02d}"
        surfaces = calibration_scene(board, R, t, rig.intrinsics.fx)
        if defects.get(i) == "no_board":
            surfaces = surfaces[1:]
        hits = trace(surfaces, rig.intrinsics, rays_xy)
        irr, stripe = stripe_irradiance(hits, rig, surfaces)
        board_img = expose(hits, surfaces, rig, Lighting(**{"ambient": rng.uniform(100, 130), **light,
                                                             "stripes_on": False}), rng)
        amb = rng.uniform(25, 45) if stripe_ambient is None else stripe_ambient
        on = Lighting(**{**light, "ambient": amb, "stripes_on": defects.get(i) != "no_stripes", "fur": False})
        stripe_img = expose(hits, surfaces, rig, on, rng, irr)
        write(out / "calib" / f"{name}_board.png", board_img)
        write(out / "calib" / f"{name}_stripes.png", stripe_img)
        truth["board_poses"].append({"name": name, "R": R.tolist(), "t": t.tolist(), "defect": defects.get(i)})
        st = stripe_truth(hits, stripe, rig, surfaces)
        np.savez_compressed(out / "truth" / f"{name}_stripes.npz", **st)  # type: ignore[arg-type]
    animal = from_mesh(mesh, mesh_length_mm) if mesh else quadruped(seed=seed)
    for view in scenes:
        _write_view(out, view, animal, rig, rays_xy, fur, seed, rng, truth, light, scene or {}, write)
    (out / "truth" / "truth.json").write_text(json.dumps(truth, indent=1))
    return out


def display_encoded(img: np.ndarray, gamma: float) -> np.ndarray:
    """The 8-bit image a camera or renderer writing display gamma ``gamma`` writes of a linear frame (uint8 or
    uint16): 255 (v / vmax)^(1 / gamma), rounded; the frame itself for gamma 1."""
    if gamma == 1.0:
        return img
    top = 65535.0 if img.dtype == np.uint16 else 255.0
    return np.clip(np.rint(255.0 * (img.astype(np.float64) / top) ** (1.0 / gamma)), 0, 255).astype(np.uint8)


def _write_view(out: Path, view: str, animal: Animal, rig: Rig, rays_xy: np.ndarray, fur: bool, seed: int,
                rng: np.random.Generator, truth: dict, light: dict, scene: dict,
                write: Callable[[Path, np.ndarray], None]) -> None:
    surfaces, R, t = animal_scene(animal, view, fur, seed, **scene)
    hits = trace(surfaces, rig.intrinsics, rays_xy)
    irr, stripe = stripe_irradiance(hits, rig, surfaces)
    ambient = rng.uniform(30, 50)
    img = expose(hits, surfaces, rig, Lighting(**{"ambient": ambient, **light, "fur": fur}), rng, irr)
    amb = expose(hits, surfaces, rig, Lighting(**{"ambient": ambient, **light, "stripes_on": False, "fur": fur}), rng)
    write(out / "scan" / f"{view}.png", img)
    write(out / "scan" / f"{view}_ambient.png", amb)
    st = stripe_truth(hits, stripe, rig, surfaces)
    np.savez_compressed(out / "truth" / f"{view}_stripes.npz", **st)  # type: ignore[arg-type]
    mesh_cam = surfaces[0]
    trimesh.Trimesh(mesh_cam.vertices, mesh_cam.faces, process=False).export(out / "truth" / f"{view}_animal.ply")
    lifted = t + R @ np.array([0.0, scene.get("platform") or 0.0, 0.0])  # the animal on a platform, if any
    truth["views"][view] = {"R_cam_world": R.tolist(), "t_cam_world": t.tolist(), "fur": fur,
                            "anatomy": _anatomy_cam(animal.anatomy, R, lifted)}


def _anatomy_cam(anatomy: dict, R: np.ndarray, t: np.ndarray) -> dict:
    """Anatomy with its points moved to camera coordinates (directions rotated only)."""
    out = dict(anatomy)
    for key in ("tail_centreline",):
        if key in out:
            out[key] = (np.asarray(out[key]) @ R.T + t).tolist()
    if "neck_centre" in out:
        out["neck_centre"] = (R @ np.asarray(out["neck_centre"]) + t).tolist()
        out["neck_axis"] = (R @ np.asarray(out["neck_axis"])).tolist()
        out["neck_up"] = (R @ np.asarray(out["neck_up"])).tolist()
        c, up, r = np.asarray(out["neck_centre"]), np.asarray(out["neck_up"]), out["neck_radius_mm"]
        toward = -c / np.linalg.norm(c)  # toward the camera, made perpendicular to the neck axis
        ax = np.asarray(out["neck_axis"])
        toward -= ax * (toward @ ax) + up * (toward @ up)
        if np.linalg.norm(toward) < 1e-6:  # looking straight along the neck's up direction (top view)
            toward = np.cross(ax, up)
        toward /= np.linalg.norm(toward)
        ang = np.deg2rad(25.0)  # landmarks 25 deg off the silhouette, on the camera side: pickable
        marks = [c + r * (np.cos(ang) * s * up + np.sin(ang) * toward) for s in (1, -1)]
        out["neck_landmarks"] = [m.tolist() for m in marks]
        out["neck_width_mm"] = float(np.linalg.norm(marks[0] - marks[1]))
    return out


def _rig_truth(rig: Rig, board: Board) -> dict:
    planes = rig.projector.planes_cam()
    abc = np.column_stack([-planes[:, 0] / planes[:, 2], -planes[:, 1] / planes[:, 2], planes[:, 3] / planes[:, 2]])
    return {
        **rig.intrinsics.to_dict(),
        "planes": planes.tolist(),
        "planes_abc": abc.tolist(),
        "projector_centre": rig.projector.centre_cam.tolist(),
        "board": {"cols": board.cols, "rows": board.rows, "square_mm": board.square_mm},
        "board_poses": [],
        "views": {},
    }


def transpose_capture(src: str | Path, dst: str | Path) -> Path:
    """Copy a capture with every image transposed (rows and columns swapped): the capture of a rig whose
    projector sits below the camera and casts stripes across the image (the transposed images are exactly
    what a camera with swapped axes sees of the mirrored scene, a valid scene in its own right; the
    chessboard is found with the same inner-corner count). rig.json is copied. Of the truth, truth.json
    (intrinsics, planes, ``stripe_axis``), the stripe points and the animal meshes are swapped: x and y of
    points and planes, u and v of pixels (the light planes then run top to bottom); the per-view json
    and the board poses are not. Returns ``dst``."""
    src, dst = Path(src), Path(dst)
    for sub in ("calib", "scan"):
        (dst / sub).mkdir(parents=True, exist_ok=True)
        for f in sorted((src / sub).iterdir()) if (src / sub).exists() else []:
            img = cv2.imread(str(f), cv2.IMREAD_UNCHANGED)
            if img is None:
                continue
            cv2.imwrite(str(dst / sub / f.name), transpose_image(img))
    (dst / "rig.json").write_text((src / "rig.json").read_text())
    if (src / "truth").exists():
        (dst / "truth").mkdir(exist_ok=True)
        truth = json.loads((src / "truth" / "truth.json").read_text())
        K = np.array(truth["camera_matrix"])
        truth["camera_matrix"] = [[K[1, 1], 0.0, K[1, 2]], [0.0, K[0, 0], K[0, 2]], [0.0, 0.0, 1.0]]
        dist = list(truth["dist_coeffs"])
        dist[2], dist[3] = dist[3], dist[2]  # p1 and p2 trade places (5-coefficient model)
        truth["dist_coeffs"] = dist
        truth["image_size"] = list(truth["image_size"])[::-1]
        truth["planes"] = swap_xy(np.array(truth["planes"])).tolist()
        truth["stripe_axis"] = "horizontal"
        (dst / "truth" / "truth.json").write_text(json.dumps(truth))
        for f in (src / "truth").glob("*_stripes.npz"):
            t = dict(np.load(f))
            t["points"], t["uv"] = swap_xy(t["points"]), t["uv"][:, ::-1]
            np.savez_compressed(dst / "truth" / f.name, **t)
        for f in (src / "truth").glob("*_animal.ply"):
            mesh: trimesh.Trimesh = trimesh.load(f, force="mesh", process=False)  # type: ignore[assignment]
            trimesh.Trimesh(swap_xy(mesh.vertices), mesh.faces[:, ::-1], process=False).export(dst / "truth" / f.name)
    return dst
