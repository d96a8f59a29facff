#!/usr/bin/env python3
"""Issue 34, item 4: is depth the missing part? An oracle initialisation.

Writes a COLMAP model with the cameras of an initial model (e.g. the built-in SfM's) and, as
its points, the ground-truth surface points of a `gems synth` scene (`gt/sparse/0`: each
training view's 32x32 probe grid, coloured from its sharp frame), carried into the initial
model's frame by the similarity between the two models' camera centres (Umeyama). Points seen
only from held-out views are left out. Training from it (`gems train SCENE --init colmap
--colmap-model OUT`) against training from the initial model alone says how much exact
geometry at the start is worth with the same cameras.

usage: oracle_model.py SCENE INIT_MODEL OUT_MODEL [--hold K]   (needs pycolmap and numpy)
"""
import argparse
import os

import numpy as np
import pycolmap


def umeyama(src, dst):
    """Similarity (s, R, t) with dst ~ s R src + t."""
    ms, md = src.mean(0), dst.mean(0)
    a, b = src - ms, dst - md
    u, sig, vt = np.linalg.svd(b.T @ a / len(src))
    d = np.eye(3)
    if np.linalg.det(u @ vt) < 0:
        d[2, 2] = -1
    r = u @ d @ vt
    s = np.trace(np.diag(sig) @ d) / (a**2).sum(1).mean()
    return s, r, md - s * r @ ms


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene")
    ap.add_argument("init_model")
    ap.add_argument("out_model")
    ap.add_argument("--hold", type=int, default=None, help="every K-th view is held out (default: the scene's hold=K file)")
    args = ap.parse_args()
    hold = args.hold
    if hold is None:
        marks = [f for f in os.listdir(args.scene) if f.startswith("hold=")]
        hold = int(marks[0].split("=")[1]) if marks else 0
    gt = pycolmap.Reconstruction(os.path.join(args.scene, "gt", "sparse", "0"))
    init = pycolmap.Reconstruction(args.init_model)
    names = sorted(im.name for im in gt.images.values())
    held = {n for i, n in enumerate(names) if hold > 0 and i % hold == 0}
    by_name = {im.name: im for im in init.images.values()}
    pairs = [(im, by_name[im.name]) for im in gt.images.values() if im.name in by_name]
    src = np.array([g.projection_center() for g, _ in pairs])
    dst = np.array([m.projection_center() for _, m in pairs])
    s, r, t = umeyama(src, dst)
    resid = np.linalg.norm(s * (r @ src.T).T + t - dst, axis=1)
    extent = max(np.linalg.norm(a - b) for a in dst for b in dst)
    print(f"{len(pairs)} cameras in both; centres after the similarity: RMSE {np.sqrt((resid**2).mean()) / extent * 100:.3f} % of the extent")
    train_ids = {im.image_id for im in gt.images.values() if im.name not in held}
    for pid in list(init.points3D.keys()):
        init.delete_point3D(pid)
    kept = 0
    for p in gt.points3D.values():
        if not any(el.image_id in train_ids for el in p.track.elements):
            continue
        init.add_point3D(s * r @ p.xyz + t, pycolmap.Track(), p.color)
        kept += 1
    os.makedirs(args.out_model, exist_ok=True)
    init.write(args.out_model)
    print(f"{kept} ground-truth surface points (of {len(gt.points3D)}; held out: {sorted(held)}) written to {args.out_model}")


if __name__ == "__main__":
    main()
