"""The gsplat half of the side-by-side benchmark (README.md beside this file).

Reads the inputs `side_by_side write DIR` made (inputs_<n>.safetensors: the same Gaussians,
15 cameras at 400x270, backgrounds and target gems reads) and times, on the GPU, with gsplat's
`rasterization`:

- forward: the 15 cameras rendered in one call;
- forward_backward: the same and the backward pass to every Gaussian parameter and to the
  cameras' view matrices (`viewmats.requires_grad`), with a fixed dL/dRGB (1e-3 everywhere);
- step: a whole GeMS step as a gsplat user writes it: render the 15 virtual cameras, their mean
  is the blurry image, (1 - lambda) L1 + lambda (1 - SSIM) against the target plus the MCMC
  opacity and scale regularisers, backward (pose gradients included), Adam on the five
  parameter groups.

each with `packed=False` and `packed=True`. A figure is the median over `--iters` calls after
`--warmup`, timed two ways: CUDA events around the call, and the wall clock with
`torch.cuda.synchronize()` before and after (what the gems side measures). Writes `--out`
(JSON) for compare.py.
"""

import argparse
import json
import statistics
import time

import numpy as np
import torch
import torch.nn.functional as F
from safetensors.numpy import load_file
from safetensors import safe_open

SIZES = [10_000, 100_000, 300_000]


def load(path, device):
    tensors = {k: torch.from_numpy(v).to(device) for k, v in load_file(path).items()}
    with safe_open(path, framework="numpy") as f:
        meta = f.metadata()
    return tensors, meta


def gaussian_window(size=11, sigma=1.5, device="cpu"):
    x = torch.arange(size, dtype=torch.float32, device=device) - size // 2
    g = torch.exp(-(x**2) / (2 * sigma**2))
    g = g / g.sum()
    return (g[:, None] * g[None, :]).expand(3, 1, size, size).contiguous()


def ssim_valid(img, target, window):
    """SSIM with an 11x11 Gaussian window (sigma 1.5), over the valid interior: the training
    SSIM of GeMS and gems (fused-ssim's padding='valid'). img, target: [H, W, 3]."""
    x = img.permute(2, 0, 1)[None]
    y = target.permute(2, 0, 1)[None]
    c1, c2 = 0.01**2, 0.03**2
    mu_x = F.conv2d(x, window, groups=3)
    mu_y = F.conv2d(y, window, groups=3)
    sxx = F.conv2d(x * x, window, groups=3) - mu_x**2
    syy = F.conv2d(y * y, window, groups=3) - mu_y**2
    sxy = F.conv2d(x * y, window, groups=3) - mu_x * mu_y
    num = (2 * mu_x * mu_y + c1) * (2 * sxy + c2)
    den = (mu_x**2 + mu_y**2 + c1) * (sxx + syy + c2)
    return (num / den).mean()


def timed(fn, warmup, iters):
    """Median milliseconds of fn by CUDA events and by the synchronised wall clock."""
    for _ in range(warmup):
        fn()
    torch.cuda.synchronize()
    events, wall = [], []
    for _ in range(iters):
        start = torch.cuda.Event(enable_timing=True)
        end = torch.cuda.Event(enable_timing=True)
        torch.cuda.synchronize()
        t0 = time.perf_counter()
        start.record()
        fn()
        end.record()
        torch.cuda.synchronize()
        wall.append((time.perf_counter() - t0) * 1e3)
        events.append(start.elapsed_time(end))
    return statistics.median(events), statistics.median(wall)


class Scene:
    """One input file on the GPU, the parameters as gems optimises them."""

    def __init__(self, path, device):
        t, meta = load(path, device)
        self.meta = meta
        self.width = int(meta["width"])
        self.height = int(meta["height"])
        self.sh_degree = int(meta["sh_degree"])
        self.means = t["means"]
        self.quats = t["quats"]
        self.log_scales = t["log_scales"]
        self.opacity_logits = t["opacity_logits"]
        self.sh = t["sh"]
        self.viewmats = t["viewmats"]
        self.Ks = t["Ks"]
        self.backgrounds = t["backgrounds"]
        self.target = t["target"]
        self.n = self.means.shape[0]
        self.cameras = self.viewmats.shape[0]


def render(rasterize, s, means, quats, log_scales, opacity_logits, sh, viewmats, packed):
    colors, alphas, _meta = rasterize(
        means=means,
        quats=quats,
        scales=torch.exp(log_scales),
        opacities=torch.sigmoid(opacity_logits),
        colors=sh,
        viewmats=viewmats,
        Ks=s.Ks,
        width=s.width,
        height=s.height,
        sh_degree=s.sh_degree,
        packed=packed,
    )
    # The background is composited here, as gsplat's rasterizer does it (colour + (1 - alpha) *
    # background): gsplat 1.5.3's packed path rejects per-camera backgrounds of shape [C, 3]
    # (the assertion in cuda/_wrapper.py's rasterize_to_pixels), so both modes take this route.
    return colors + (1.0 - alphas) * s.backgrounds[:, None, None, :]  # [C, H, W, 3]


def bench_size(rasterize, s, packed, warmup, iters):
    out = {"n": s.n, "packed": packed}

    def forward():
        with torch.no_grad():
            render(
                rasterize, s, s.means, s.quats, s.log_scales, s.opacity_logits, s.sh,
                s.viewmats, packed,
            )

    out["forward_ms_events"], out["forward_ms"] = timed(forward, warmup, iters)

    params = [
        p.clone().requires_grad_(True)
        for p in (s.means, s.quats, s.log_scales, s.opacity_logits, s.sh)
    ]
    d_rgb = torch.full(
        (s.cameras, s.height, s.width, 3), 1e-3, device=s.means.device
    )

    def forward_backward():
        for p in params:
            p.grad = None
        viewmats = s.viewmats.clone().requires_grad_(True)
        colors = render(rasterize, s, *params, viewmats, packed)
        colors.backward(d_rgb)
        return viewmats.grad

    out["forward_backward_ms_events"], out["forward_backward_ms"] = timed(
        forward_backward, warmup, iters
    )

    # The GeMS step. Learning rates and loss weights: the file's metadata (gems's defaults).
    m = s.meta
    lam = float(m["ssim_lambda"])
    opacity_reg = float(m["opacity_reg"])
    scale_reg = float(m["scale_reg"])
    means, quats, log_scales, opacity_logits = [
        p.clone().requires_grad_(True)
        for p in (s.means, s.quats, s.log_scales, s.opacity_logits)
    ]
    # gems gives the SH degree 0 and the rest their own learning rates, as 3DGS does.
    sh_dc = s.sh[:, :1].clone().requires_grad_(True)
    sh_rest = s.sh[:, 1:].clone().requires_grad_(True)
    adam = torch.optim.Adam(
        [
            {"params": [means], "lr": float(m["lr_means"])},
            {"params": [quats], "lr": float(m["lr_quats"])},
            {"params": [log_scales], "lr": float(m["lr_log_scales"])},
            {"params": [opacity_logits], "lr": float(m["lr_opacity_logits"])},
            {"params": [sh_dc], "lr": float(m["lr_sh_dc"])},
            {"params": [sh_rest], "lr": float(m["lr_sh_rest"])},
        ],
        eps=float(m["adam_eps"]),
        betas=(float(m["adam_beta1"]), float(m["adam_beta2"])),
    )
    window = gaussian_window(device=s.means.device)

    def gems_step():
        adam.zero_grad(set_to_none=True)
        viewmats = s.viewmats.clone().requires_grad_(True)
        sh_all = torch.cat([sh_dc, sh_rest], dim=1)
        colors = render(
            rasterize, s, means, quats, log_scales, opacity_logits, sh_all, viewmats, packed
        )
        blurry = colors.mean(dim=0)
        l1 = (blurry - s.target).abs().mean()
        loss = (1 - lam) * l1 + lam * (1 - ssim_valid(blurry, s.target, window))
        loss = loss + opacity_reg * torch.sigmoid(opacity_logits).mean()
        loss = loss + scale_reg * torch.exp(log_scales).mean()
        loss.backward()
        adam.step()
        # gems reads the cameras' pose gradients back every step: so does this.
        return viewmats.grad.cpu()

    out["step_ms_events"], out["step_ms"] = timed(gems_step, warmup, iters)
    out["gpu_peak_mib"] = torch.cuda.max_memory_allocated() / 2**20
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("dir", help="the folder `side_by_side write` made")
    ap.add_argument("--out", help="JSON to write (default DIR/gsplat.json)")
    ap.add_argument("--iters", type=int, default=20)
    ap.add_argument("--warmup", type=int, default=3)
    ap.add_argument("--sizes", default=",".join(map(str, SIZES)))
    args = ap.parse_args()

    import gsplat
    from gsplat import rasterization

    device = torch.device("cuda")
    rows = []
    for n in [int(v) for v in args.sizes.split(",")]:
        s = Scene(f"{args.dir}/inputs_{n}.safetensors", device)
        for packed in (False, True):
            torch.cuda.reset_peak_memory_stats()
            row = bench_size(rasterization, s, packed, args.warmup, args.iters)
            print(json.dumps(row), flush=True)
            rows.append(row)
    result = {
        "engine": f"gsplat {gsplat.__version__}",
        "adapter": torch.cuda.get_device_name(),
        "torch": torch.__version__,
        "cuda": torch.version.cuda,
        "iters": args.iters,
        "results": rows,
    }
    path = args.out or f"{args.dir}/gsplat.json"
    with open(path, "w") as f:
        json.dump(result, f, indent=2)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
