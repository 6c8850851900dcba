"""Where a sample's time goes, matfit vs Mitsuba 3, path depth by path depth.

    source bench/mitsuba_env.sh && python bench/depth.py [--matfit PATH] [--spp N] [--reps K]
        [--scene figure6|office]

The benchmark's scene (figure6 with a diffuse floor, 256x192, exported to Mitsuba by `matfit
export mitsuba`; with `--scene office`, compare.py's big mesh: office-large all diffuse, 1.2M
triangles, 480x270) rendered with max_depth 1 (the camera ray and what it sees), 2 (plus direct
light: one shadow ray and one BSDF ray), 3 and 8 (the benchmark's), one thread each, N spp.
matfit: its own "rendered in" (the render alone: the BVH is built as the scene loads; no image
writing); Mitsuba `llvm_ad_rgb`: `mi.render` on a second call (kernels compiled by the first),
medians of K runs.
Prints ns per sample (pixels x spp) at each depth and the cost of the segments each step adds,
and the ratio: where matfit's per-sample cost exceeds Mitsuba's. 1-2 min.
"""
import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import crosscheck as cc  # noqa: E402

DEPTHS = (1, 2, 3, 8)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--matfit", default=None)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--scene", choices=["figure6", "office"], default="figure6")
    a = ap.parse_args()
    exe = cc.find_matfit(a.matfit)
    import drjit as dr
    import mitsuba as mi
    mi.set_variant("llvm_ad_rgb")
    mi.set_log_level(mi.LogLevel.Error)
    dr.set_thread_count(1)
    w, h = (256, 192) if a.scene == "figure6" else (480, 270)
    samples = w * h * a.spp
    rows = []
    with tempfile.TemporaryDirectory() as d:
        if a.scene == "office":
            base, _ = cc.office_diffuse(d, w, h)
        else:
            base = cc.figure6_variant(d, '{ type = "diffuse", rho_d = [0.2, 0.3, 0.4] }', w, h)
        text = open(base).read()
        for depth in DEPTHS:
            sub = os.path.join(d, f"d{depth}")
            os.makedirs(sub)
            # Beside the base scene, whose files it names relative to itself.
            scene = os.path.join(d, f"scene_d{depth}.toml")
            t, n = re.subn(r"^max_depth = \d+$", f"max_depth = {depth}", text, flags=re.M)
            assert n == 1, "figure6 has no max_depth line"
            open(scene, "w").write(t)
            subprocess.run([exe, "export", "mitsuba", scene, "-o", os.path.join(sub, "mi")],
                           check=True, capture_output=True)
            out = os.path.join(sub, "x.pfm")
            mf = []
            for _ in range(a.reps):
                r = subprocess.run([exe, "--threads", "1", "render", scene, "-o", out, "--spp",
                                    str(a.spp)], check=True, capture_output=True, text=True,
                                   env=dict(os.environ, MATFIT_LOG="info"))
                m = re.search(r"rendered in ([0-9.]+)", r.stderr)
                mf.append(float(m.group(1)))
            ms = mi.load_file(os.path.join(sub, "mi", "scene.xml"), optimize=False)
            mt = []
            for i in range(a.reps + 1):
                t0 = time.perf_counter()
                img = mi.render(ms, spp=a.spp, seed=i)
                dr.eval(img)
                dr.sync_thread()
                mt.append(time.perf_counter() - t0)
            rows.append((depth, statistics.median(mf) / samples * 1e9,
                         statistics.median(mt[1:]) / samples * 1e9))

    what = "figure6 (diffuse floor)" if a.scene == "figure6" else "office-large (diffuse)"
    print(f"{what} {w}x{h}, {a.spp} spp, 1 thread, medians of {a.reps}; ns per sample\n")
    print("| max_depth | matfit | Mitsuba llvm_ad_rgb | ratio | added by this step: matfit | "
          "Mitsuba | ratio |")
    print("|---:|---:|---:|---:|---:|---:|---:|")
    prev = None
    for depth, m, s in rows:
        step = "| | | |" if prev is None else \
            f"| {m - prev[1]:.0f} | {s - prev[2]:.0f} | {(m - prev[1]) / (s - prev[2]):.2f} |"
        print(f"| {depth} | {m:.0f} | {s:.0f} | {m / s:.2f} {step}")
        prev = (depth, m, s)


if __name__ == "__main__":
    main()
