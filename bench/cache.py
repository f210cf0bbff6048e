"""Every view in the render cache, scanned and scored: the quick check of a labelling change.

    python bench/cache.py dump OUT.json [--cache /tmp/bodyscan-bench] [--surface]
    python bench/cache.py compare BEFORE.json AFTER.json [--view top]
    python bench/cache.py variants [--cache /tmp/bodyscan-bench] [--out /tmp/bodyscan-variants]
    python bench/cache.py hashes OUT.json [--cache /tmp/bodyscan-bench]
    python bench/cache.py identical BEFORE.json AFTER.json

The other benches render their views into the cache (``/tmp/bodyscan-bench`` by default) once; ``dump`` scans
each of them with the checkout's code (the five-seed bench's, the robustness benches' at both sizes: 272 views
on 2026-12-01) and writes per view the animal's true crossings, how many of its centres were labelled and how
many of those right, the background's, the body length and height, and the count of wrong labels by their
distance from the truth, and the same length and height definitions applied to the true stripe points; with
``--surface`` also the share of the animal's points within 2 mm of its true surface and their RMS
(``bench/scan.py``'s figures; 11-14 minutes a dump when this was written; 37 s without ``--surface`` on 2026-12-04; two run side by side on this 2-core host). ``compare`` prints the
totals of two dumps over the views both hold (views with at least half the animal labelled and 95 % of that
right; animal centres right and wrong; background centres wrong; the wrong labels of the views placed in the
first dump by their shift from the truth; over those views, how many lengths and heights lie within 1 % of the
truth's, their mean error and how many lie over it by more than 1 and 2 %; where both dumps have them, how
many views have 99.5 % of their points within 2 mm, the mean share and the RMS) and every view whose animal
labels or length moved. A dump without the truth's figures (made before they were added) is compared with the
other dump's. To compare two versions, dump with each checkout's own copy (it imports the checkout it lies in:
``python ../other/bench/cache.py dump B.json``).

``variants`` fills a second cache (``--out``) with views the benches do not render and a labelling change
can break unseen: each of the five-seed bench's 3072 px renders found in ``--cache`` under a softer lens (a
Gaussian blur of 0.6 and of 1.2 px on top of the simulator's optics, as ``bench/frames.py``'s ``blur``; the
truth is the render's own, linked), and the five seeds' configurations rendered at 1536 px (120 views, about
2 minutes); ``dump --cache`` that directory to score them. On 2026-12-02 these showed what the benches had not: a
hind leg and tail left unlabelled from the side at 1536 px, and under the blur (length -26 %).

``hashes`` writes per cached view a SHA-256 of its scan's points, stripes and pixels (the cloud and the scene) and of
its measurements (a view the scan refuses: its error), half a minute on this host; ``identical`` prints how many views
two such files disagree on, and which. A speed change is said to move nothing only when ``identical`` finds none
(hash with each checkout's own copy, as for ``dump``).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.common import ANIMAL  # noqa: E402
from measurement.body import measure  # noqa: E402
from measurement.calibration import load_calibration  # noqa: E402
from measurement.errors import MeasurementError  # noqa: E402
from measurement.images import read_image  # noqa: E402
from measurement.pipeline import scan  # noqa: E402
from measurement.simulate.truth import match_crossings  # noqa: E402


def score_view(cap: Path, view: str, surface: bool = False) -> dict:
    """The scores of one cached view (see the module docstring)."""
    try:
        r = scan(read_image(cap / "scan" / f"{view}.png"), load_calibration(cap / "truth" / "truth.json"), view)
    except MeasurementError as exc:
        return {"error": str(exc)[:200]}
    t = dict(np.load(cap / "truth" / f"{view}_stripes.npz"))
    tk, kind = match_crossings(r.scene_uv, t)
    an, bg = kind == ANIMAL, (kind == 2) | (kind == 3)
    wrong = an & (r.scene_stripe != tk) & (tk >= 0)
    diffs, counts = np.unique(r.scene_stripe[wrong] - tk[wrong], return_counts=True)
    on = t["kind"] == ANIMAL
    ref = measure(t["points"][on], t["stripe"][on], np.rint(t["uv"][on, 1]).astype(np.int64), view) if on.any() else {}
    return {
        "truth": int((t["kind"] == ANIMAL).sum()),
        "animal_labelled": int(an.sum()), "animal_right": int((r.scene_stripe[an] == tk[an]).sum()),
        "bg": int(bg.sum()), "bg_right": int((r.scene_stripe[bg] == tk[bg]).sum()),
        "length": r.measurements.get("body_length_mm"), "height": r.measurements.get("body_height_mm"),
        "points": int(len(r.points)), "wrong_by_shift": {int(d): int(n) for d, n in zip(diffs, counts, strict=True)},
        "length_truth": ref.get("body_length_mm"), "height_truth": ref.get("body_height_mm"),
        **(_surface(cap, view, r.points) if surface else {}),
    }


def _surface(cap: Path, view: str, points: np.ndarray) -> dict:
    """The share of ``points`` (N, 3) within 2 mm of the view's true animal surface, and their RMS (mm)."""
    import trimesh

    from bench.scan import surface_distance

    if len(points) == 0:
        return {}
    d = surface_distance(trimesh.load(cap / "truth" / f"{view}_animal.ply", process=False), points)
    within = d < 2.0
    return {"within_2mm": float(within.mean()),
            "rms_within_mm": float(np.sqrt(np.mean(d[within] ** 2))) if within.any() else None}


def dump(cache: Path, out: Path, surface: bool = False) -> None:
    t0 = time.perf_counter()
    views: dict[str, dict] = {}
    for cap in sorted(p for p in cache.iterdir() if (p / "truth" / "truth.json").exists()):
        for view in json.loads((cap / "truth" / "truth.json").read_text()).get("views", {}):
            if (cap / "scan" / f"{view}.png").exists():
                views[f"{cap.name}/{view}"] = score_view(cap, view, surface)
    out.write_text(json.dumps({"views": views}, indent=1))
    print(f"{len(views)} views scored in {time.perf_counter() - t0:.0f} s -> {out}")


BLURS = (0.6, 1.2)  # px: ``variants``' softer lenses
VARIANT_SEEDS = (4, 8, 9, 10, 12)  # bench/scan.py --seeds


def variants(cache: Path, out: Path) -> None:
    """Write ``variants``' views into ``out`` (see the module docstring); views already there are kept."""
    import cv2

    from bench.frames import blur
    from bench.scan import capture_for

    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    for cap in sorted(cache.glob("scan-3072x2048-*")):
        if not (cap / "truth" / "truth.json").exists():
            continue
        for sigma in BLURS:
            dst = out / f"blur{round(10 * sigma):02d}-{cap.name}"
            (dst / "scan").mkdir(parents=True, exist_ok=True)
            if not (dst / "truth").exists():
                (dst / "truth").symlink_to(cap / "truth", target_is_directory=True)
            for view in json.loads((cap / "truth" / "truth.json").read_text()).get("views", {}):
                src, to = cap / "scan" / f"{view}.png", dst / "scan" / f"{view}.png"
                if src.exists() and not to.exists():
                    cv2.imwrite(str(to), blur(read_image(src), sigma))
    for seed in VARIANT_SEEDS:
        for stripes in (40, 50):
            for fur in (True, False):
                capture_for(out, stripes, fur, (1536, 1024), seed)
    print(f"variants in {out} ({time.perf_counter() - t0:.0f} s): bench/cache.py dump OUT.json --cache {out}")


def placed(v: dict) -> bool:
    return "error" not in v and v["animal_labelled"] >= 0.5 * v["truth"] and v["animal_right"] >= 0.95 * v["animal_labelled"]


def _shown(v: dict) -> str:
    if "error" in v:
        return "refused"
    share = v["animal_right"] / max(1, v["animal_labelled"])
    return f"{share:.2%} of {v['animal_labelled']}/{v['truth']} labelled, length {v['length']}"


def compare(before: Path, after: Path, view: str | None) -> None:
    a, b = (json.loads(p.read_text())["views"] for p in (before, after))
    keys = [k for k in sorted(set(a) & set(b)) if view is None or k.endswith("/" + view)]

    def total(d: dict, f) -> int:
        return sum(f(d[k]) for k in keys if "error" not in d[k])

    rows = (("views placed (half labelled, 95 % of that right)", placed),
            ("animal centres right", lambda v: v["animal_right"]),
            ("animal centres wrong", lambda v: v["animal_labelled"] - v["animal_right"]),
            ("background centres wrong", lambda v: v["bg"] - v["bg_right"]))
    print(f"{len(keys)} views in both dumps")
    for name, f in rows:
        x, y = total(a, f), total(b, f)
        print(f"  {name}: {x} -> {y} ({y - x:+d})")
    # the wrong labels of the views placed in the first dump, by how far off they are
    shifts: dict[int, list[int]] = {}
    for j, d in enumerate((a, b)):
        for k in keys:
            if placed(a[k]) and "error" not in d[k]:
                for shift, count in d[k].get("wrong_by_shift", {}).items():
                    shifts.setdefault(int(shift), [0, 0])[j] += count
    if shifts:
        top = sorted(shifts.items(), key=lambda kv: -max(kv[1]))[:8]
        print("  wrong labels in the views placed before, by label - truth: "
              + ", ".join(f"{s:+d}: {x} -> {y}" for s, (x, y) in top))
    for name in ("length", "height"):
        print(_accuracy(name, [k for k in keys if placed(a[k])], a, b))
    both = [k for k in keys if placed(a[k]) and all(d[k].get("rms_within_mm") is not None for d in (a, b))]
    if both:
        w = [np.array([d[k]["within_2mm"] for k in both]) for d in (a, b)]
        rms = [np.array([d[k]["rms_within_mm"] for k in both]) for d in (a, b)]
        print(f"  points of the {len(both)} views placed before: views with 99.5 % within 2 mm "
              f"{int(np.sum(w[0] >= 0.995))} -> {int(np.sum(w[1] >= 0.995))}, mean share within 2 mm "
              f"{w[0].mean():.2%} -> {w[1].mean():.2%}, views with RMS <= 0.5 mm {int(np.sum(rms[0] <= 0.5))} -> "
              f"{int(np.sum(rms[1] <= 0.5))}, mean RMS {rms[0].mean():.3f} -> {rms[1].mean():.3f} mm")
    for k in keys:
        va, vb = a[k], b[k]
        if any(va.get(f) != vb.get(f) for f in ("error", "animal_labelled", "animal_right", "length")):
            print(f"  {k}: {_shown(va)} -> {_shown(vb)}")


def _accuracy(name: str, keys: list[str], a: dict, b: dict) -> str:
    """One line: over ``keys``, the ``name`` (length or height) of dumps a and b against the truth's."""
    errs: list[list[float]] = [[], []]
    for k in keys:
        truth = b[k].get(f"{name}_truth") or a[k].get(f"{name}_truth")
        got = [d[k].get(name) for d in (a, b)]
        if truth and all(g is not None for g in got):
            for j in (0, 1):
                errs[j].append(got[j] / truth - 1)
    if not errs[0]:
        return f"  {name}: no truth figures in either dump"
    e = [np.array(x) for x in errs]
    parts = [f"within 1 % {int(np.sum(np.abs(e[0]) <= 0.01))} -> {int(np.sum(np.abs(e[1]) <= 0.01))}",
             f"mean |error| {np.mean(np.abs(e[0])):.2%} -> {np.mean(np.abs(e[1])):.2%}",
             f"over +1 % {int(np.sum(e[0] > 0.01))} -> {int(np.sum(e[1] > 0.01))}",
             f"over +2 % {int(np.sum(e[0] > 0.02))} -> {int(np.sum(e[1] > 0.02))}"]
    return f"  {name}s of the {len(e[0])} views placed before, against the truth's: " + ", ".join(parts)


def digest(result) -> str:
    """SHA-256 of a ``ScanResult``'s arrays and its measurements (JSON, keys sorted)."""
    h = hashlib.sha256()
    for a in (result.points, result.stripe, result.uv, result.scene_points, result.scene_stripe, result.scene_uv):
        h.update(np.ascontiguousarray(a).tobytes())
    h.update(json.dumps(result.measurements, sort_keys=True, default=str).encode())
    return h.hexdigest()


def hashes(cache: Path, out: Path) -> None:
    """``digest`` of every cached view's scan into ``out`` (JSON: capture/view -> hash or error)."""
    found: dict[str, str] = {}
    for cap in sorted(c for c in cache.iterdir() if (c / "scan").is_dir() and (c / "truth" / "truth.json").exists()):
        cal = load_calibration(cap / "truth" / "truth.json")
        for view in ("side", "top"):
            frame = cap / "scan" / f"{view}.png"
            if frame.exists():
                try:
                    found[f"{cap.name}/{view}"] = digest(scan(read_image(frame), cal, view))
                except MeasurementError as e:
                    found[f"{cap.name}/{view}"] = f"error: {e}"
    out.write_text(json.dumps(found, indent=0))
    print(f"{len(found)} views hashed into {out}")


def identical(before: Path, after: Path) -> None:
    """How many views two ``hashes`` files disagree on, by view, and which."""
    a, b = json.loads(before.read_text()), json.loads(after.read_text())
    differ = [k for k in sorted(set(a) & set(b)) if a[k] != b[k]]
    by_view = {v: sum(k.endswith("/" + v) for k in differ) for v in ("side", "top")}
    print(f"{len(differ)} of {len(set(a) & set(b))} views differ (side {by_view['side']}, top {by_view['top']}); "
          f"{len(set(a) ^ set(b))} in one file only")
    for k in differ:
        print("  " + k)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    d = sub.add_parser("dump")
    d.add_argument("out", type=Path)
    d.add_argument("--cache", type=Path, default=Path("/tmp/bodyscan-bench"))
    d.add_argument("--surface", action="store_true", help="score the points against the true surface too")
    w = sub.add_parser("variants")
    w.add_argument("--cache", type=Path, default=Path("/tmp/bodyscan-bench"))
    w.add_argument("--out", type=Path, default=Path("/tmp/bodyscan-variants"))
    c = sub.add_parser("compare")
    c.add_argument("before", type=Path)
    c.add_argument("after", type=Path)
    c.add_argument("--view", choices=("side", "top", "front", "back"))
    h = sub.add_parser("hashes")
    h.add_argument("out", type=Path)
    h.add_argument("--cache", type=Path, default=Path("/tmp/bodyscan-bench"))
    i = sub.add_parser("identical")
    i.add_argument("before", type=Path)
    i.add_argument("after", type=Path)
    args = ap.parse_args()
    if args.cmd == "dump":
        dump(args.cache, args.out, args.surface)
    elif args.cmd == "variants":
        variants(args.cache, args.out)
    elif args.cmd == "hashes":
        hashes(args.cache, args.out)
    elif args.cmd == "identical":
        identical(args.before, args.after)
    else:
        compare(args.before, args.after, args.view)


if __name__ == "__main__":
    main()
