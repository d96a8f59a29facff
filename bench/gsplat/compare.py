"""Puts gems.json (`side_by_side run`) and gsplat.json (bench.py) side by side: one markdown
table, each figure the synchronised wall-clock median of the same run on the same GPU, and the
ratio gems / gsplat (below 1: gems is faster) against gsplat's faster packing."""

import json
import sys


def main():
    if len(sys.argv) != 3:
        sys.exit("usage: compare.py gems.json gsplat.json")
    with open(sys.argv[1]) as f:
        gems = json.load(f)
    with open(sys.argv[2]) as f:
        gsplat = json.load(f)
    print(f"GPU: {gsplat['adapter']} (gems: {gems['adapter']}); {gsplat['engine']}, "
          f"torch {gsplat['torch']}, CUDA {gsplat['cuda']}; "
          f"{gems['cameras']} cameras at {gems['width']}x{gems['height']}, SH degree 3; "
          f"medians of {gems['iters']} (gems) and {gsplat['iters']} (gsplat) calls\n")
    print("| Gaussians | what | gems ms | gsplat ms, packed=False | gsplat ms, packed=True "
          "| gems / gsplat |")
    print("|---|---|---|---|---|---|")
    for row in gems["results"]:
        n = row["n"]
        theirs = {r["packed"]: r for r in gsplat["results"] if r["n"] == n}
        for key, what in [
            ("forward_ms", "forward"),
            ("forward_backward_ms", "forward + backward (pose gradients)"),
            ("step_ms", "GeMS step"),
        ]:
            unpacked = theirs.get(False, {}).get(key)
            packed = theirs.get(True, {}).get(key)
            best = min(v for v in (unpacked, packed) if v is not None) if theirs else None
            fmt = lambda v: "—" if v is None else f"{v:.2f}"
            ratio = "—" if best is None else f"{row[key] / best:.2f}"
            print(f"| {n} | {what} | {row[key]:.2f} | {fmt(unpacked)} | {fmt(packed)} "
                  f"| {ratio} |")


if __name__ == "__main__":
    main()
