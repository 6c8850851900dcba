#!/usr/bin/env python3
"""Smoke test of the Mitsuba 3 setup: load cbox.xml in scalar_rgb and llvm_ad_rgb, render at
low res/spp, print time per render and mean pixel value.

    source bench/mitsuba_env.sh
    python bench/mitsuba_smoke.py [--res 64] [--spp 16] [--threads 2] [--scene PATH]
"""
import argparse
import os
import time

import drjit as dr
import mitsuba as mi
import numpy as np

DEFAULT_SCENE = os.path.join(os.path.dirname(os.path.abspath(__file__)),
                             "..", "..", "shared", "data", "cornell-box", "cbox.xml")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--scene", default=os.path.normpath(DEFAULT_SCENE))
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--variants", default="scalar_rgb,llvm_ad_rgb")
    args = ap.parse_args()

    if "llvm" in args.variants and not os.environ.get("DRJIT_LIBLLVM_PATH"):
        print("warning: DRJIT_LIBLLVM_PATH unset; source bench/mitsuba_env.sh")

    for variant in args.variants.split(","):
        mi.set_variant(variant)
        mi.set_log_level(mi.LogLevel.Warn)
        # One thread pool (nanothread) serves both the scalar render loop and the LLVM
        # backend's kernels; set it *after* set_variant, before the first render.
        dr.set_thread_count(args.threads)
        t0 = time.perf_counter()
        scene = mi.load_file(args.scene, optimize=False, res=args.res, spp=args.spp)
        t_load = time.perf_counter() - t0
        times, means = [], []
        for i in range(args.repeats):
            t0 = time.perf_counter()
            img = mi.render(scene, seed=i)
            arr = np.array(img)  # forces evaluation in JIT variants
            times.append(time.perf_counter() - t0)
            means.append(arr.mean(axis=(0, 1)))
        m = np.mean(means, axis=0)
        print(f"{variant:12s} threads={dr.thread_count()} res={args.res} spp={args.spp} "
              f"load={t_load:.2f}s render(first)={times[0]:.3f}s "
              f"render(rest,median)={np.median(times[1:]) if len(times) > 1 else float('nan'):.3f}s "
              f"mean RGB=({m[0]:.4f}, {m[1]:.4f}, {m[2]:.4f}) mean={m.mean():.4f}")


if __name__ == "__main__":
    main()
