"""The peer of gems's SfM: COLMAP 4 through pycolmap (CPU SIFT, exhaustive matching, the
incremental and the global mapper) on a scene's `images/`, scored against its
`poses_bounds.npy` the way `sfm_eval` scores gems (registered views; camera-centre RMSE after a
Sim(3) alignment, in % of the reference path's extent; mean relative-rotation error over the
registered pairs; focal error).

    pip install pycolmap numpy
    python3 crates/gems-init/scripts/pycolmap_peer.py SCENE [SCENE…] [--work DIR]
        [--mappers incremental,global] [--focal F]

One line per scene and mapper. `--focal` gives COLMAP the focal (pixels at the images' size)
and keeps it fixed, as `sfm_eval --focal` does for gems; without it COLMAP starts from its
default guess and refines it. Not run in CI (pycolmap is not a dependency of gems).
"""

import argparse
import pathlib
import shutil
import time

import numpy as np
import pycolmap


def reference(scene):
    """Camera centres, camera-to-world rotations (OpenCV axes) and the focal of an LLFF
    poses_bounds.npy (N x 17), whose rotation columns are (down, right, back)."""
    rows = np.load(scene / "poses_bounds.npy")
    poses = rows[:, :15].reshape(-1, 3, 5)
    c2w = np.stack([poses[:, :, 1], poses[:, :, 0], -poses[:, :, 2]], axis=2)
    return poses[:, :, 3], c2w, float(poses[0, 2, 4])


def angle_deg(r):
    """Rotation angle of a 3x3 rotation matrix, degrees."""
    return float(np.degrees(np.arccos(np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0))))


def size_of(scene):
    """(height, width) of the images, from the poses file's hwf column."""
    rows = np.load(scene / "poses_bounds.npy")
    hwf = rows[0, :15].reshape(3, 5)[:, 4]
    return float(hwf[0]), float(hwf[1])


def umeyama(src, dst):
    """Similarity (s, R, t) minimising |s R src + t - dst|^2 (Umeyama 1991)."""
    mu_s, mu_d = src.mean(0), dst.mean(0)
    xs, xd = src - mu_s, dst - mu_d
    cov = xd.T @ xs / len(src)
    u, d, vt = np.linalg.svd(cov)
    sign = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        sign[2, 2] = -1
    r = u @ sign @ vt
    var = (xs**2).sum() / len(src)
    s = np.trace(np.diag(d) @ sign) / var
    return s, r, mu_d - s * r @ mu_s


def score(rec, names, centres, rotations, focal_ref):
    """Registered views, centre RMSE / extent, mean relative-rotation error over all registered
    pairs (degrees, as sfm_eval's), focal error of the largest reconstruction."""
    est, ref, rot_est, rot_ref = [], [], [], []
    for image in rec.images.values():
        stem = pathlib.Path(image.name).stem
        if stem in names:
            c2w = image.cam_from_world().inverse()
            est.append(c2w.translation)
            rot_est.append(c2w.rotation.matrix())
            ref.append(centres[names.index(stem)])
            rot_ref.append(rotations[names.index(stem)])
    pairs = [
        angle_deg((rot_est[i].T @ rot_est[j]).T @ (rot_ref[i].T @ rot_ref[j]))
        for i in range(len(rot_est))
        for j in range(i + 1, len(rot_est))
    ]
    rot_err = float(np.mean(pairs)) if pairs else None
    extent = max(np.linalg.norm(a - b) for a in centres for b in centres)
    rmse = None
    if len(est) >= 3:
        est, ref = np.array(est), np.array(ref)
        s, r, t = umeyama(est, ref)
        aligned = (s * (r @ est.T)).T + t
        rmse = float(np.sqrt(((aligned - ref) ** 2).sum(1).mean()) / extent)
    cam = next(iter(rec.cameras.values()))
    focal = float(cam.focal_length) if hasattr(cam, "focal_length") else float(cam.params[0])
    return len(est), rmse, rot_err, focal / focal_ref - 1.0


def run(scene, work, mapper, focal):
    images = scene / "images"
    names = sorted(p.stem for p in images.iterdir() if p.is_file())
    centres, rotations, focal_ref = reference(scene)
    out = work / scene.name / mapper
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    db = out / "database.db"
    reader = pycolmap.ImageReaderOptions()
    reader.camera_model = "SIMPLE_PINHOLE"
    if focal is not None:
        h, w = size_of(scene)
        reader.camera_params = f"{focal},{w / 2},{h / 2}"
    t0 = time.time()
    pycolmap.extract_features(
        db, images, camera_mode=pycolmap.CameraMode.SINGLE, reader_options=reader,
        device=pycolmap.Device.cpu,
    )
    pycolmap.match_exhaustive(db, device=pycolmap.Device.cpu)
    if mapper == "incremental":
        opts = pycolmap.IncrementalPipelineOptions()
        if focal is not None:
            opts.ba_refine_focal_length = False
        recs = pycolmap.incremental_mapping(db, images, out, options=opts)
    else:
        opts = pycolmap.GlobalPipelineOptions()
        if focal is not None:
            opts.mapper.bundle_adjustment.refine_focal_length = False
        recs = pycolmap.global_mapping(db, images, out, options=opts)
    seconds = time.time() - t0
    if not recs:
        return f"{scene}: COLMAP {pycolmap.__version__} {mapper}: no reconstruction ({seconds:.1f}s)"
    rec = max(recs.values(), key=lambda r: r.num_reg_images())
    registered, rmse, rot_err, focal_err = score(rec, names, centres, rotations, focal_ref)
    rmse_text = "—" if rmse is None else f"{100 * rmse:.3f} %"
    rot_text = "—" if rot_err is None else f"{rot_err:.2f}°"
    return (
        f"{scene}: COLMAP {pycolmap.__version__} {mapper}: registered {registered}/{len(names)}, "
        f"centres {rmse_text} of the extent, rel. rot err {rot_text}, "
        f"focal {100 * focal_err:+.1f} %, {seconds:.1f}s"
    )


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scenes", nargs="+", type=pathlib.Path)
    ap.add_argument("--work", type=pathlib.Path, default=pathlib.Path("/tmp/pycolmap_peer"))
    ap.add_argument("--mappers", default="incremental,global")
    ap.add_argument("--focal", type=float)
    args = ap.parse_args()
    for scene in args.scenes:
        for mapper in args.mappers.split(","):
            print(run(scene, args.work, mapper, args.focal), flush=True)


if __name__ == "__main__":
    main()
