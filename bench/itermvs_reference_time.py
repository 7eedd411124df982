#!/usr/bin/python3
"""CPU time per reference view of the IterMVS network, the reference that
docs/benchmarks.md compares dispmvs_bench with.

IterMVS is not part of this project: point --itermvs_path at a checkout of
its public repository (the measurement in docs/benchmarks.md used the models/
files of its commit dc20a238). This script only builds inputs and times the
network's own test-mode forward: the feature net on all views, the depth
initialisation, `iteration` GRU updates and the upsampling, i.e. the
model(imgs, proj_matrices, depth_min, depth_max) call that its eval.py runs
per sample. Random weights: the amount of work does not depend on them (a
fixed iteration count, no early exit).

Needs Debian's python3-torch (apt-get install python3-torch) and its python:
    /usr/bin/python3 bench/itermvs_reference_time.py --itermvs_path ITERMVS \
        --height 480 --width 640 --views 5 --threads 2 --warmup 2 --reps 5
"""
import argparse
import os
import resource
import statistics
import sys
import time

import numpy as np
import torch


def load_pipeline(itermvs_path):
    """IterMVS's Pipeline class from its checkout (models/__init__.py imports
    `models.net`, so the checkout's root goes on the module path)."""
    if not os.path.isfile(os.path.join(itermvs_path, "models", "net.py")):
        sys.exit(f"--itermvs_path {itermvs_path}: no models/net.py there (a checkout of IterMVS?)")
    sys.path.insert(0, os.path.abspath(itermvs_path))
    from models import Pipeline  # pylint: disable=import-outside-toplevel
    return Pipeline


def build_inputs(height, width, views, depth_min=1.0, depth_max=10.0, seed=0):
    """Inputs shaped exactly like the repository's dataset classes produce them
    (after the DataLoader adds the batch dim, B=1):
      imgs['level_l']          [B, V, 3, H/2^l, W/2^l], values in [-1, 1]
      proj_matrices['level_l'] [B, V, 4, 4]: extrinsic (world->cam) with its top
                               3x4 block replaced by K_l @ E[:3, :4], where K_l is
                               the full-res K with rows 0,1 scaled by 1/2^l
      depth_min, depth_max     [B] (float64 from the DataLoader; net casts .float())
    """
    rng = np.random.RandomState(seed)
    f = 0.8 * width
    K = np.array([[f, 0.0, width / 2.0],
                  [0.0, f, height / 2.0],
                  [0.0, 0.0, 1.0]], dtype=np.float32)

    # reference camera at origin; sources translated by small baselines
    # (~3-6% of the near depth... up to 0.2 units with depth range 1..10)
    offsets = [(0.10, 0.0, 0.0), (-0.10, 0.0, 0.0), (0.0, 0.10, 0.0), (0.0, -0.10, 0.0),
               (0.20, 0.0, 0.0), (-0.20, 0.0, 0.0), (0.0, 0.20, 0.0), (0.0, -0.20, 0.0)]
    extrinsics = []
    for v in range(views):
        E = np.eye(4, dtype=np.float32)
        if v > 0:
            c = np.array(offsets[(v - 1) % len(offsets)], dtype=np.float32)
            c *= 1.0 + (v - 1) // len(offsets)  # further views: larger baseline
            E[:3, 3] = -c  # world->cam translation for camera centre c (R = I)
        extrinsics.append(E)

    proj = {}
    for level in range(4):  # same scaling chain as datasets/*.py: 0.125, then *2 ...
        Kl = K.copy()
        Kl[:2, :] *= 1.0 / (2 ** level)
        mats = []
        for E in extrinsics:
            P = E.copy()
            P[:3, :4] = np.matmul(Kl, P[:3, :4])
            mats.append(P)
        proj[f"level_{level}"] = torch.from_numpy(np.stack(mats))[None]  # [1,V,4,4]

    imgs = {}
    img0 = rng.uniform(-1.0, 1.0, size=(1, views, 3, height, width)).astype(np.float32)
    imgs["level_0"] = torch.from_numpy(img0)
    for level in (1, 2, 3):
        imgs[f"level_{level}"] = torch.nn.functional.interpolate(
            imgs["level_0"][0], size=(height // 2 ** level, width // 2 ** level),
            mode="bilinear", align_corners=False)[None]

    dmin = torch.tensor([depth_min], dtype=torch.float64)
    dmax = torch.tensor([depth_max], dtype=torch.float64)
    return imgs, proj, dmin, dmax


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--itermvs_path", required=True, help="a checkout of the IterMVS repository")
    ap.add_argument("--height", type=int, default=480)
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--views", type=int, default=5, help="total views incl. reference (eval.py --n_views default 5)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--warmup", type=int, default=2)
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--iteration", type=int, default=4, help="GRU iterations (eval.py default 4)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    if args.height % 32 or args.width % 32:
        sys.exit(f"height/width must be multiples of 32 (got {args.height}x{args.width}): "
                 "the 1/8-res features feed a CorrNet with two stride-2 convs + "
                 "output_padding=1 transposed convs, and the feature FPN needs exact /2 sizes")
    if args.views < 2:
        sys.exit("--views must be >= 2 (reference + at least one source)")

    torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)

    model = load_pipeline(args.itermvs_path)(iteration=args.iteration, test=True)
    model.eval()
    nparams = sum(p.numel() for p in model.parameters())

    imgs, proj, dmin, dmax = build_inputs(args.height, args.width, args.views, seed=args.seed)

    print(f"torch {torch.__version__}  threads={torch.get_num_threads()}  "
          f"interop={torch.get_num_interop_threads()}  params={nparams}")
    print(f"input HxW={args.height}x{args.width}  views={args.views} (1 ref + {args.views - 1} src)  "
          f"iteration={args.iteration}  warmup={args.warmup}  reps={args.reps}")

    def forward():
        return model(imgs, proj, dmin, dmax)

    times = []
    with torch.no_grad():
        for i in range(args.warmup):
            t0 = time.perf_counter()
            out = forward()
            print(f"warmup {i}: {time.perf_counter() - t0:.3f} s", flush=True)
        for i in range(args.reps):
            t0 = time.perf_counter()
            out = forward()
            dt = time.perf_counter() - t0
            times.append(dt)
            print(f"rep {i}: {dt:.3f} s", flush=True)

    if args.reps == 0:
        with torch.no_grad():
            out = forward()
    d = out["depths_upsampled"]
    c = out["confidence_upsampled"]
    print(f"output depths_upsampled {tuple(d.shape)} (range {d.min().item():.3f}..{d.max().item():.3f}), "
          f"confidence_upsampled {tuple(c.shape)}, finite={bool(torch.isfinite(d).all())}")
    if times:
        print(f"median {statistics.median(times):.3f} s  min {min(times):.3f} s  "
              f"per reference view ({args.height}x{args.width}, {args.views} views, "
              f"{args.iteration} iters, {args.threads} threads)")
    rss_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # KiB on Linux
    print(f"peak RSS {rss_kb / 1024:.1f} MiB")


if __name__ == "__main__":
    main()
