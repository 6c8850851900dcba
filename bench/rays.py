"""Ray casting alone, matfit vs Mitsuba 3 (Embree) on the same rays, one thread each.

    source bench/mitsuba_env.sh && python bench/rays.py [--matfit PATH] [--rays N] [--repeat K]
        [--scene figure6|office]

The scene is the benchmark's figure6 with a diffuse floor (its 38 triangles), or with
`--scene office` the big mesh of `compare.py` (scenes/office-large made all diffuse by its
generator, 1.2M triangles), exported to Mitsuba by `matfit export mitsuba`. Rays: N origins
uniform in the room (1 cm inside its walls; for the office, inside the scene's bounding box,
so some start inside furniture),
directions uniform on the sphere, and for shadow queries a length of half the distance to the
closest hit: none is blocked, so each walks the tree to the end as a lit point's shadow ray
does; seed 1. matfit
times `Scene::intersect` (closest hit with its hit record), the BVH query alone, and
`Scene::occluded`, through `matfit bench rays --ray-file`; Mitsuba times `ray_intersect` (full
SurfaceInteraction: t, p, n, shading frame, uv), `ray_intersect_preliminary` and `ray_test` on
the same rays as one wavefront (`llvm_ad_rgb`, kernels compiled by a first call, medians of K
calls). Mitsuba's figures include reading and writing its arrays; matfit's a loop over a slice.
This is where the path tracer's time goes (two thirds of a figure6 render), so the ratio says
how much of the forward-throughput gap (bench/RESULTS.md) is traversal.
"""
import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import crosscheck as cc  # noqa: E402

ROOM_LO, ROOM_HI = np.array([-2.0, 0.0, -7.0]), np.array([2.0, 3.0, 0.0])


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--matfit", default=None)
    ap.add_argument("--rays", type=int, default=1 << 20)
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--scene", choices=["figure6", "office"], default="figure6")
    a = ap.parse_args()
    exe = cc.find_matfit(a.matfit)
    import drjit as dr
    import mitsuba as mi
    mi.set_variant("llvm_ad_rgb")
    dr.set_thread_count(1)

    with tempfile.TemporaryDirectory() as d:
        lo, hi = ROOM_LO, ROOM_HI
        if a.scene == "office":
            scene, _ = cc.office_diffuse(d, 480, 270)
        else:
            scene = cc.figure6_variant(d, '{ type = "diffuse", rho_d = [0.2, 0.3, 0.4] }',
                                       256, 192)
        subprocess.run([exe, "export", "mitsuba", scene, "-o", os.path.join(d, "mi")],
                       check=True, capture_output=True)
        ms = mi.load_file(os.path.join(d, "mi", "scene.xml"), optimize=False)
        if a.scene == "office":
            lo, hi = np.array(ms.bbox().min), np.array(ms.bbox().max)
        rng = np.random.default_rng(1)
        n = a.rays
        o = lo + 0.01 + (hi - lo - 0.02) * rng.random((n, 3))
        dirs = rng.normal(size=(n, 3))
        dirs /= np.linalg.norm(dirs, axis=1)[:, None]
        o, dirs = o.astype(np.float32), dirs.astype(np.float32)
        ray = mi.Ray3f(mi.Point3f(*[mi.Float(o[:, i]) for i in range(3)]),
                       mi.Vector3f(*[mi.Float(dirs[:, i]) for i in range(3)]))
        t_hit = np.array(ms.ray_intersect_preliminary(ray).t, dtype=np.float32)
        length = np.where(np.isfinite(t_hit), 0.5 * t_hit, 1.0).astype(np.float32)
        shadow = mi.Ray3f(ray.o, ray.d, mi.Float(length))

        def timed(f, out):
            ts = []
            for _ in range(a.repeat + 1):
                t = time.perf_counter()
                r = f()
                dr.eval(*out(r))
                dr.sync_thread()
                ts.append(time.perf_counter() - t)
            return statistics.median(ts[1:]) / n * 1e9  # the first call compiles

        mi_full = timed(lambda: ms.ray_intersect(ray),
                        lambda si: (si.t, si.p, si.n, si.sh_frame.n, si.sh_frame.s, si.uv))
        mi_pre = timed(lambda: ms.ray_intersect_preliminary(ray), lambda pi: (pi.t, pi.prim_index))
        mi_test = timed(lambda: ms.ray_test(shadow), lambda m: (m,))

        path = os.path.join(d, "rays.bin")
        np.concatenate([o, dirs, length[:, None]], axis=1).astype("<f4").tofile(path)
        out = subprocess.run([exe, "bench", "rays", "--scene", scene, "--ray-file", path,
                              "--repeat", str(a.repeat)], check=True, capture_output=True,
                             text=True).stdout
        num = lambda key: float(re.search(key + r" ([0-9.]+) ns", out).group(1))  # noqa: E731
        mf_full, mf_bvh, mf_shadow = (num("hit record"), num("BVH query alone"), num("shadow"))
        m8 = re.search(r"packets of 8: BVH query ([0-9.]+) ns, shadow ([0-9.]+) ns", out)
        mf_bvh8, mf_shadow8 = float(m8.group(1)), float(m8.group(2))

    what = ("figure6 (diffuse floor)" if a.scene == "figure6"
            else "office-large (diffuse, 1.2M triangles)")
    print(f"{n} rays in {what}, 1 thread, ns per ray (median of {a.repeat})\n")
    print("| query | matfit | Mitsuba 3 llvm_ad_rgb (Embree) | matfit / Mitsuba |")
    print("|---|---:|---:|---:|")
    for name, m, s in [("closest hit + hit record", mf_full, mi_full),
                       ("closest hit, BVH query alone", mf_bvh, mi_pre),
                       ("shadow ray (any hit), half the hit distance", mf_shadow, mi_test),
                       ("closest hit, BVH query alone, packets of 8", mf_bvh8, mi_pre),
                       ("shadow ray, packets of 8", mf_shadow8, mi_test)]:
        print(f"| {name} | {m:.1f} | {s:.1f} | {m / s:.2f} |")


if __name__ == "__main__":
    main()
