"""Scan robustness to how the frame is formed: the five-seed bench's views as another renderer or camera
might hand them over.

    python bench/frames.py [--seeds 4,8] [--frames dark,vignette,blur] [--size 3072x2048] [--cache /tmp/bodyscan-bench]
                           [--save DIR]

Each frame transform is applied to the stripe image of every view of ``bench/scan.py``'s configurations (40 and
50 stripes, fur and clean, side and top) before the scan; the truth is the render's own. ``none``: the frame
as rendered; ``dark``: every gray level halved (half the exposure or gain, noise included); ``vignette``: a
cos^4 fall-off to 0.55 of the centre's light in the corners; ``blur``: a Gaussian of sigma 1.2 px on top of the
simulator's optics (a softer lens or focus); ``jpeg``: encoded as a JPEG of quality 85; ``bright``: every gray level
times 2.5, clipped at 255 (overexposed: flat-topped stripes); ``specks``: 0.05 % of the pixels stuck at 255 or 0
(hot and dead pixels); ``noisy``: Gaussian noise of 4 gray levels more. Per view the bench's figures, then per transform how many views
have at least 95 % of the animal's labelled crossings right and how many lengths and heights lie within 1 %.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.scan import capture_for, evaluate, pct_err  # noqa: E402
from measurement.images import read_image  # noqa: E402


def _gray(img: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def dark(img: np.ndarray) -> np.ndarray:
    return _gray(img.astype(np.float64) * 0.5)


def vignette(img: np.ndarray, corner: float = 0.55) -> np.ndarray:
    """cos^4 of the field angle, scaled so the corners keep ``corner`` of the centre's light."""
    h, w = img.shape[:2]
    y, x = np.mgrid[0:h, 0:w]
    radius = np.hypot((x - w / 2) / (w / 2), (y - h / 2) / (w / 2)) / np.hypot(1.0, h / w)  # 1 at a corner
    corner_angle = np.arccos(corner ** 0.25)
    return _gray(img.astype(np.float64) * np.cos(np.arctan(radius * np.tan(corner_angle))) ** 4)


def blur(img: np.ndarray, sigma: float = 1.2) -> np.ndarray:
    return _gray(cv2.GaussianBlur(img.astype(np.float64), (0, 0), sigma))


def jpeg(img: np.ndarray, quality: int = 85) -> np.ndarray:
    """Encoded and decoded as a JPEG of this quality (a camera's or a web upload's default)."""
    ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise RuntimeError("JPEG encoding failed")
    return cv2.imdecode(buf, cv2.IMREAD_UNCHANGED)


def bright(img: np.ndarray, gain: float = 2.5) -> np.ndarray:
    """Every gray level times ``gain``, clipped: an overexposed frame, the stripes' crests flat at 255."""
    return _gray(img.astype(np.float64) * gain)


def specks(img: np.ndarray, share: float = 5e-4, seed: int = 0) -> np.ndarray:
    """``share`` of the pixels stuck: half of them at 255 (hot), half at 0 (dead)."""
    out = img.copy()
    rng = np.random.default_rng(seed)
    at = rng.choice(out.size, int(share * out.size), replace=False)
    out.ravel()[at[: len(at) // 2]] = 255
    out.ravel()[at[len(at) // 2:]] = 0
    return out


def noisy(img: np.ndarray, sigma: float = 4.0, seed: int = 0) -> np.ndarray:
    """Gaussian read noise of ``sigma`` gray levels on top of the simulator's own."""
    return _gray(img.astype(np.float64) + np.random.default_rng(seed).normal(0.0, sigma, img.shape))


FRAMES = {"none": None, "dark": dark, "vignette": vignette, "blur": blur, "jpeg": jpeg, "bright": bright,
          "specks": specks, "noisy": noisy}


def save(cap: Path, view: str, name: str, out: Path) -> Path:
    """Write the capture ``cap``'s ``view`` under the frame transform ``name`` as the capture
    ``out/NAME-CAPTURE`` (its scan image; the truth linked to the original's); returns that directory."""
    dst = out / f"{name}-{cap.name}"
    (dst / "scan").mkdir(parents=True, exist_ok=True)
    if not (dst / "truth").exists():
        (dst / "truth").symlink_to((cap / "truth").resolve(), target_is_directory=True)
    img, transform = read_image(cap / "scan" / f"{view}.png"), FRAMES[name]
    cv2.imwrite(str(dst / "scan" / f"{view}.png"), img if transform is None else transform(img))
    return dst


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", default="3072x2048")
    ap.add_argument("--cache", default="/tmp/bodyscan-bench")
    ap.add_argument("--seeds", default="4,8")
    ap.add_argument("--frames", default="none,dark,vignette,blur")
    ap.add_argument("--save", type=Path, default=None,
                    help="also write each transformed view as a capture DIR/FRAME-CAPTURE (scan/VIEW.png, the truth "
                         "linked) for bench/mislabels.py, bench/pieces.py and bench/cache.py dump --cache DIR")
    args = ap.parse_args()
    size = tuple(int(v) for v in args.size.split("x"))
    cache = Path(args.cache)
    cache.mkdir(parents=True, exist_ok=True)
    frames = args.frames.split(",")
    unknown = [f for f in frames if f not in FRAMES]
    if unknown:
        ap.error(f"unknown frame transform {', '.join(unknown)} (choose from {', '.join(FRAMES)})")
    print("frame     config       view  animal pts  labels right  within 2 mm  length err  height err  saturated")
    totals = {f: [0, 0, 0, 0] for f in frames}  # views, placed, lengths, heights
    for seed in (int(v) for v in args.seeds.split(",")):
        for cfg in ("40-fur", "40-clean", "50-fur", "50-clean"):
            stripes, kind = cfg.split("-")
            cap = capture_for(cache, int(stripes), kind == "fur", size, seed)
            for view in ("side", "top"):
                for name in frames:
                    if args.save is not None:
                        save(cap, view, name, args.save)
                    e = evaluate(cap, view, frame=FRAMES[name])
                    length, height = e["body_length_mm"], e["body_height_mm"]
                    t = totals[name]
                    t[0] += 1
                    t[1] += e["animal_label_right"] >= 0.95
                    t[2] += length is not None and abs(length / e["body_length_truth_mm"] - 1) <= 0.01
                    t[3] += height is not None and abs(height / e["body_height_truth_mm"] - 1) <= 0.01
                    print(f"{name:9s} {cfg + '/' + str(seed):12s} {view:4s} {e['animal_points']:7d}/{e['animal_truth_crossings']:<6d}"
                          f" {e['animal_label_right']:8.2%}   {e['within_2mm']:9.2%}   "
                          f"{pct_err(length, e['body_length_truth_mm'])}     "
                          f"{pct_err(height, e['body_height_truth_mm'])}     {e['saturated_share'] or 0:.2%}", flush=True)
    for name, (n, placed, lengths, heights) in totals.items():
        print(f"{name}: {placed} of {n} views with >= 95 % of the animal right, lengths within 1 % {lengths}, "
              f"heights {heights}")


if __name__ == "__main__":
    main()
