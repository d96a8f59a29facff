"""Is the built-in SfM's camera error under heavy blur a basin it was grown into, or the optimum
of its own observations? A diagnostic for `gems synth` scenes (ground truth needed).

For each SCENE (a folder with `images/` and the generator's `poses_bounds.npy`) and the gems SfM
model made on it (`gems sfm SCENE -o MODEL`, best with `--focal` so that the focal is not a
second unknown), the model's own observations are bundle-adjusted by COLMAP 4 (pycolmap: Cauchy
loss of scale 1 px, intrinsics held) twice: from the gems cameras, and from the ground-truth
mid-exposure cameras, Sim(3)-aligned into the model's frame. In both, every point is first
re-triangulated from its track, so the two robust costs compare like with like.

    pip install pycolmap numpy
    python3 crates/gems-init/scripts/ba_from_truth.py SCENE:MODEL [SCENE:MODEL…] 2>/dev/null

One line per scene: the gems model, and the two adjusted results, each scored as
`pycolmap_peer.py` scores (centre RMSE after Sim(3) in % of the path extent, mean
relative-rotation error over all pairs) with the rotation from the first to the last camera;
then both results' robust costs (sum of log(1 + r²/px²)) and median residuals. With the
generator's sub-frame poses (`poses_bounds_subframes.npy`) also the median residual at the
truth along and across each point's blur streak (its projection at the exposure's first and last
sub-frame).

If the adjustment started from the truth stays near it at a lower cost, the SfM was grown into a
wrong basin and a better initialisation (rotation averaging) would help; if it drifts as far, or
its basin costs more, the observations themselves put the optimum away from the truth.
Not run in CI (pycolmap is not a dependency of gems).
"""

import os
import pathlib
import sys

import numpy as np
import pycolmap

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from pycolmap_peer import angle_deg, reference, score, umeyama  # noqa: E402


def cameras(rec):
    """Camera-to-world rotation and centre per image stem."""
    out = {}
    for image in rec.images.values():
        if image.has_pose:
            c2w = image.cam_from_world().inverse()
            out[pathlib.Path(image.name).stem] = (c2w.rotation.matrix(), c2w.translation)
    return out


def summary(rec, names, centres, rotations, focal):
    _, rmse, rot_err, _ = score(rec, names, centres, rotations, focal)
    cams = cameras(rec)
    reg = [n for n in names if n in cams]
    turn = angle_deg(cams[reg[0]][0].T @ cams[reg[-1]][0])
    return f"{100 * rmse:.2f} % / {rot_err:.2f}° / turn {turn:.1f}°"


def observations(rec):
    """(point id, image, observed pixel) for every track element."""
    for pid, point in rec.points3D.items():
        for el in point.track.elements:
            image = rec.images[el.image_id]
            yield pid, image, np.asarray(image.points2D[el.point2D_idx].xy)


def project(k, c2w, x):
    q = k @ (c2w[0].T @ (x - c2w[1]))
    return q[:2] / q[2]


def robust_cost(rec):
    k = next(iter(rec.cameras.values())).calibration_matrix()
    cams = cameras(rec)
    r2 = np.array([
        ((xy - project(k, cams[pathlib.Path(im.name).stem], rec.points3D[pid].xyz)) ** 2).sum()
        for pid, im, xy in observations(rec)
    ])
    return np.log1p(r2).sum(), np.sqrt(np.median(r2))


def retriangulate(rec):
    """Each point by linear (DLT) triangulation from its track under the current cameras."""
    cam = next(iter(rec.cameras.values()))
    rows = {}
    for pid, image, xy in observations(rec):
        pose = image.cam_from_world()
        m = np.hstack([pose.rotation.matrix(), pose.translation[:, None]])
        xn = cam.cam_from_img(xy)
        rows.setdefault(pid, []).extend([xn[0] * m[2] - m[0], xn[1] * m[2] - m[1]])
    for pid, a in rows.items():
        x = np.linalg.svd(np.array(a))[2][-1]
        rec.points3D[pid].xyz = x[:3] / x[3]


def adjust(rec):
    opts = pycolmap.BundleAdjustmentOptions()
    opts.refine_focal_length = False
    opts.refine_principal_point = False
    opts.refine_extra_params = False
    opts.ceres.loss_function_type = pycolmap.LossFunctionType.CAUCHY
    opts.ceres.loss_function_scale = 1.0
    opts.print_summary = False
    pycolmap.bundle_adjustment(rec, opts)


def llff_c2w(row):
    m = row[:15].reshape(3, 5)
    return np.stack([m[:, 1], m[:, 0], -m[:, 2]], 1), m[:, 3]


def along_across(rec, names, truth, subframes, to_truth):
    """Median |residual| at the truth along and across each point's blur streak."""
    k = next(iter(rec.cameras.values())).calibration_matrix()
    s, r, t = to_truth
    along, across = [], []
    for pid, image, xy in observations(rec):
        stem = pathlib.Path(image.name).stem
        v = names.index(stem)
        x = s * r @ rec.points3D[pid].xyz + t
        d = project(k, llff_c2w(subframes[v, -1]), x) - project(k, llff_c2w(subframes[v, 0]), x)
        if np.linalg.norm(d) < 1e-6:
            continue
        u = d / np.linalg.norm(d)
        res = xy - project(k, truth[stem], x)
        along.append(abs(res @ u))
        across.append(abs(res[0] * u[1] - res[1] * u[0]))
    return np.median(along), np.median(across)


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    print("scene | gems model | gems, adjusted | truth, adjusted | robust cost gems / truth "
          "(median residual) | at the truth: median |residual| along / across the streak")
    for arg in sys.argv[1:]:
        scene, model = (pathlib.Path(p) for p in arg.split(":"))
        names = sorted(p.stem for p in (scene / "images").iterdir() if p.is_file())
        centres, rotations, focal = reference(scene)
        if len(centres) != len(names):
            sys.exit(f"{scene}: {len(names)} images but {len(centres)} poses")
        truth = {n: (rotations[i], centres[i]) for i, n in enumerate(names)}
        sparse = model / "sparse" / "0"

        rec = pycolmap.Reconstruction(sparse)
        gems = summary(rec, names, centres, rotations, focal)
        retriangulate(rec)
        adjust(rec)
        from_gems, cost_gems = summary(rec, names, centres, rotations, focal), robust_cost(rec)

        rec = pycolmap.Reconstruction(sparse)
        cams = cameras(rec)
        common = [n for n in names if n in cams]
        s, r, t = umeyama(np.array([truth[n][1] for n in common]),
                          np.array([cams[n][1] for n in common]))
        for image in rec.images.values():
            stem = pathlib.Path(image.name).stem
            if stem in truth:
                rot = r @ truth[stem][0]
                rec.frames[image.frame_id].rig_from_world = pycolmap.Rigid3d(
                    pycolmap.Rotation3d(rot.T), -rot.T @ (s * r @ truth[stem][1] + t))
        retriangulate(rec)
        streak = ""
        subframes = scene / "poses_bounds_subframes.npy"
        if subframes.exists():
            a, c = along_across(rec, names, truth, np.load(subframes),
                                (1 / s, r.T, -r.T @ t / s))
            streak = f" | {a:.2f} / {c:.2f} px"
        adjust(rec)
        from_truth, cost_truth = summary(rec, names, centres, rotations, focal), robust_cost(rec)
        print(f"{scene.name} | {gems} | {from_gems} | {from_truth} | {cost_gems[0]:.0f} / "
              f"{cost_truth[0]:.0f} ({cost_gems[1]:.2f} / {cost_truth[1]:.2f} px){streak}")


if __name__ == "__main__":
    main()
