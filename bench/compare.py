#!/usr/bin/env python3
"""matfit vs Mitsuba 3 on the same machine in one run (issue 7). Run it through bench/run.sh.

    bash bench/run.sh [--quick]            # builds matfit, sets up Mitsuba, runs this
    python bench/compare.py [--quick] [--matfit PATH] [--out DIR] [--md FILE]
    python bench/compare.py --scene glossy [--before PATH]   # part 1 only, on scenes/glossy

The scene is scenes/figure6 with its anisotropic Ward floor replaced by a diffuse one of
rho_d FLOOR_RHO (not grey 0.5, so that no group starts at its answer), rendered at RES (the
scene's 512x384 halved; a quarter with --quick), max_depth 8 in both renderers (the scene's;
Mitsuba's meaning). Mitsuba loads the XML written by `matfit export mitsuba`. Both tools use
--threads cores (matfit `--threads`, Mitsuba `dr.set_thread_count`).

1. Forward rendering
   - equal spp: matfit, Mitsuba `llvm_ad_rgb` (first call, which compiles its kernels with an
     empty kernel cache, and warm calls) and `scalar_rgb`, all at EQ_SPP: render time and
     samples/s (pixels x spp / render time).
   - the reference: Mitsuba `llvm_ad_rgb` at REF_SPP (two halves A and B with disjoint seeds;
     it is also the photo of part 2). Its agreement with matfit is checked group by group
     (the mean of matfit's longest equal-time render over each group's eroded mask).
   - equal time: each tool renders with the spp that fills a time budget at its measured
     throughput; RMSE against the reference over all pixels except the light and a 2-pixel band
     around it (whose anti-aliasing noise, 30 vs 0.5, would otherwise dominate). The
     reference's own noise is removed: RMSE^2 = mean|x - ref|^2 - mean|A - B|^2 / 4.
   - a big mesh (issue 24): scenes/office-large, all diffuse (its generator's --diffuse), at
     BIG's size (1.2M triangles, 46 groups): equal-spp throughput of matfit and Mitsuba llvm
     (warm), loading time, matfit's peak RSS, and the two images' group means.
2. Inverse rendering from the reference image, every visible non-emitting group starting from
   grey 0.5, true values known: the maximum absolute error over every channel of every visible
   group against time.
   - matfit `recover SCENE PHOTO --exposure 1`, defaults otherwise; the error after each line of
     log.jsonl (its `elapsed`) plus the process's start-up before the recovery began (process
     wall time - results.json's total_s, which overestimates it by the time taken to write the
     outputs: conservative for matfit).
   - Mitsuba: `prb` integrator (max_depth 8), Adam on the L2 image loss as in Mitsuba's
     inverse-rendering tutorials, one RGB variable per group (objects of a group share it; the
     scene is loaded with optimize=False so each object keeps its own BSDF), clamped to [0, 1]
     after each step, seed = iteration. Several (learning rate, spp per iteration, schedule)
     configurations run for PILOT seconds each; the one with the lowest error over the last
     quarter of its pilot continues up to LONG seconds (20x matfit's time to 0.01, within
     bounds). Mitsuba's clock counts scene loading and its iterations, not its JIT compilation
     (two warm-up iterations are run and discarded first; their extra time is reported).
   - "reached" = the time after which the error stays at or below the threshold until the end
     of the run (a first touch is given in brackets when earlier).
3. Cross-renderer accuracy: matfit recovers the diffuse-floor scene (the run of part 2) and a
   mirror-floor variant (rho_s 0.8) from photos rendered by Mitsuba; true vs recovered values.

--scene glossy measures part 1 alone (Mitsuba has no Ward BRDF, and parts 2-3 expect diffuse
and mirror groups) on scenes/glossy with its Ward sphere replaced by the lobe `matfit export
mitsuba` fits to it, a Beckmann microfacet lobe (GLOSSY_SPHERE), which Mitsuba renders exactly;
at half the scene's 400x300. --forward-only measures part 1 alone on figure6. --before PATH
adds a second matfit binary (e.g. a build of the main branch) to the equal-spp and equal-time
tables, taking turns with the first, so that a change is measured before and after in one run.
Every equal-time row has its efficiency 1 / (RMSE^2 x time) and its ratio to Mitsuba
llvm_ad_rgb's at the same budget.

Writes OUT/{forward,inverse,cross}.json, the images, the convergence plot OUT/convergence.svg
(copied next to the Markdown file) and the Markdown report (--md; default bench/RESULTS.md in
full mode, OUT/RESULTS.md with --quick).
"""
import argparse
import datetime
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
import tomllib

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.normpath(os.path.join(HERE, ".."))
sys.path.insert(0, HERE)
import crosscheck as cc  # noqa: E402  (read_pfm, eroded_masks, figure6_variant, ...)

FLOOR_RHO = (0.2, 0.3, 0.4)
# scenes/glossy's Ward sphere (rho_d 0.2, rho_s 0.3, alpha 0.15) as `matfit export mitsuba`
# approximates it: Lambert + a Beckmann lobe of the fitted alpha and scale k = 0.698.
GLOSSY_SPHERE = ('{ type = "microfacet", distribution = "beckmann", rho_d = 0.2, '
                 'rho_s = 0.2094, alpha = 0.1463 }')
MIRROR_RHO = 0.8
THRESHOLDS = (0.05, 0.02, 0.01)

# Per mode: resolution, spp of the equal-spp renders, time budgets of the equal-time renders
# (s), reference spp, mirror photo spp, Mitsuba inverse configurations, pilot and long budgets
# (s), matfit recover's extra options.
MODES = {
    "full": dict(
        res=(256, 192), eq_spp=64, budgets=(4.0, 16.0), ref_spp=4096, mirror_spp=2048,
        configs=[
            dict(lr=0.05, spp=8),
            dict(lr=0.02, spp=4),
            dict(lr=0.05, spp=4, halflife=40, lr_min=0.002),
            dict(lr=0.05, spp=2, halflife=60, lr_min=0.001),
        ],
        pilot=60.0, long_min=60.0, long_max=420.0, recover_args=["--white-unseen"],
    ),
    "quick": dict(
        res=(128, 96), eq_spp=16, budgets=(0.5, 2.0), ref_spp=512, mirror_spp=512,
        configs=[
            dict(lr=0.05, spp=4),
            dict(lr=0.05, spp=4, halflife=30, lr_min=0.002),
        ],
        pilot=8.0, long_min=8.0, long_max=24.0,
        recover_args=["--white-unseen", "--final-spp", "16"],
    ),
}
# scenes/glossy (--scene glossy): its 400x300 halved, a quarter with --quick.
GLOSSY_RES = {"full": (200, 150), "quick": (100, 75)}
# The big mesh (issue 24): scenes/office-large made all diffuse by its generator, at this size.
BIG = {
    "full": dict(res=(480, 270), spp=16, triangles=1.2e6),
    "quick": dict(res=(240, 135), spp=4, triangles=1.2e6),
}
EQ_RUNS = 3  # equal-spp timings: runs of each renderer, interleaved, median quoted
CHUNK = 256  # largest spp per Mitsuba llvm render call (memory: pixels x spp lanes)


# ----------------------------------------------------------------------------------------------
# helpers


def log(msg):
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", flush=True)


def run(cmd, **kw):
    r = subprocess.run(cmd, capture_output=True, text=True, **kw)
    if r.returncode != 0:
        sys.exit(f"compare.py: {' '.join(cmd)} failed ({r.returncode}):\n{r.stdout}{r.stderr}")
    return r


def write_exr(mi, path, img):
    mi.util.write_bitmap(path, np.asarray(img, dtype=np.float32), write_async=False)


def scene_truth(toml_path):
    """{group: (model, rho_d[3], rho_s[3])} from the first object of each group; emitters are
    omitted. Model: 'diffuse', 'mirror' or 'diffuse_mirror' (the variants use no other)."""
    sc = tomllib.load(open(toml_path, "rb"))

    def rgb(v):
        return np.array([v] * 3 if isinstance(v, (int, float)) else v, dtype=np.float64)

    truth = {}
    for o in sc["object"]:
        if o["group"] in truth or "emission" in o:
            continue
        m = o["material"]
        zero = np.zeros(3)
        if m["type"] == "diffuse":
            truth[o["group"]] = ("diffuse", rgb(m["rho_d"]), zero)
        elif m["type"] == "mirror":
            truth[o["group"]] = ("mirror", zero, rgb(m["rho_s"]))
        elif m["type"] == "diffuse_mirror":
            truth[o["group"]] = ("diffuse_mirror", rgb(m["rho_d"]), rgb(m["rho_s"]))
        else:
            sys.exit(f"compare.py: {toml_path}: unexpected material {m['type']}")
    return truth


def group_objects(toml_path):
    """{group: [object names]} in file order (the exporter names Mitsuba shapes after them)."""
    sc = tomllib.load(open(toml_path, "rb"))
    out = {}
    for o in sc["object"]:
        out.setdefault(o["group"], []).append(o["name"])
    return out


def params_rhos(params):
    """(rho_d, rho_s) of a matfit parameter dict (log.jsonl / results.json): a level without
    rho_d has none; the perfect-mirror level (no free parameter) has rho_s 1."""
    rd = np.array(params.get("rho_d", [0.0] * 3), dtype=np.float64)
    if "rho_s" in params:
        rs = np.array(params["rho_s"], dtype=np.float64)
    elif "rho_d" in params:
        rs = np.zeros(3)
    else:
        rs = np.ones(3)
    return rd, rs


def max_err(current, truth, groups):
    """Largest |recovered - true| over rho_d and rho_s channels of `groups`."""
    e = 0.0
    for g in groups:
        rd, rs = current[g]
        _, td, ts = truth[g]
        e = max(e, float(np.abs(rd - td).max()), float(np.abs(rs - ts).max()))
    return e


def reach_times(curve, thr):
    """(time after which err stays <= thr to the end, first time err <= thr); None if never.
    `curve`: [(t, err)] in time order."""
    first = next((t for t, e in curve if e <= thr), None)
    stay = None
    for t, e in reversed(curve):
        if e > thr:
            break
        stay = t
    return stay, first


def dilate(mask, r):
    h, w = mask.shape
    pad = np.pad(mask, r)
    out = np.zeros_like(mask)
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            out |= pad[r + dy:r + dy + h, r + dx:r + dx + w]
    return out


def fmt_t(stay_first, budget_note=""):
    stay, first = stay_first
    if stay is None:
        return f"not reached{budget_note}" if first is None else f"not held (first {first:.1f} s)"
    if first is not None and first < stay - 1e-9:
        return f"{stay:.1f} s (first {first:.1f} s)"
    return f"{stay:.1f} s"


# ----------------------------------------------------------------------------------------------
# renderers


class Matfit:
    def __init__(self, exe, threads, name="matfit"):
        self.exe, self.threads, self.name = exe, threads, name

    def cmd(self, *args):
        return [self.exe, "--threads", str(self.threads), *args]

    def render(self, scene, out, spp, seed):
        """Image, render time (matfit's own 'rendered in'), process wall time, CPU time."""
        env = dict(os.environ, MATFIT_LOG="info")
        ru0 = os.times()
        t0 = time.perf_counter()
        r = run(self.cmd("render", scene, "-o", out, "--spp", str(spp), "--seed", str(seed)),
                env=env)
        wall = time.perf_counter() - t0
        ru1 = os.times()
        cpu = (ru1.children_user - ru0.children_user) + (ru1.children_system - ru0.children_system)
        t_render = None
        for line in r.stderr.splitlines():
            if "rendered in" in line:
                t_render = float(line.split("rendered in")[1].split()[0])
        if t_render is None:
            sys.exit(f"compare.py: no 'rendered in' in matfit's log:\n{r.stderr}")
        return cc.read_pfm(out).astype(np.float64), t_render, wall, cpu


class Mitsuba:
    def __init__(self, threads):
        import drjit as dr
        import mitsuba as mi
        self.mi, self.dr, self.threads = mi, dr, threads
        dr.set_thread_count(threads)
        self.scenes = {}

    def scene(self, variant, xml, **kw):
        mi = self.mi
        mi.set_variant(variant)
        mi.set_log_level(mi.LogLevel.Error)
        self.dr.set_thread_count(self.threads)
        key = (variant, xml, tuple(sorted(kw.items())))
        if key not in self.scenes:
            mi.file_resolver().prepend(os.path.dirname(xml))
            t0 = time.perf_counter()
            self.scenes[key] = (mi.load_file(xml, **kw), time.perf_counter() - t0)
        return self.scenes[key]

    def render(self, variant, xml, spp, seed):
        """Image (mean of calls of <= CHUNK spp), wall time, CPU time of this process."""
        sc, _ = self.scene(variant, xml)
        mi = self.mi
        c0, t0 = time.process_time(), time.perf_counter()
        acc, done, k = None, 0, 0
        while done < spp:
            n = min(CHUNK, spp - done) if variant.startswith("llvm") else spp - done
            img = np.array(mi.render(sc, spp=n, seed=seed * 1000 + k), dtype=np.float64)[..., :3]
            acc = img * n if acc is None else acc + img * n
            done += n
            k += 1
        return acc / spp, time.perf_counter() - t0, time.process_time() - c0


# ----------------------------------------------------------------------------------------------
# 1. forward


def forward(mf, ms, cfg, d, scene, xml, ids, light_id, group_names, before=None):
    w, h = cfg["res"]
    px = w * h
    res = {"res": [w, h]}
    off_light = ~dilate(ids == light_id, 2)

    # Equal spp. Mitsuba llvm first (empty kernel cache: its first call compiles).
    spp = cfg["eq_spp"]
    rows = []
    log(f"forward: equal spp ({spp}) ...")
    _, t_load = ms.scene("llvm_ad_rgb", xml)
    llvm_first = ms.render("llvm_ad_rgb", xml, spp, seed=1)
    _, t_load_s = ms.scene("scalar_rgb", xml)
    scal = ms.render("scalar_rgb", xml, spp, seed=1)
    # The machine is noisy: matfit and Mitsuba's warm calls take turns, EQ_RUNS each, and the
    # table quotes medians (matfit's runs use one seed: the same image each time).
    mruns, llvm_warm, bruns = [], [], []
    for k in range(EQ_RUNS):
        mruns.append(mf.render(scene, os.path.join(d, "matfit_eq.pfm"), spp, 1))
        if before:
            bruns.append(before.render(scene, os.path.join(d, "before_eq.pfm"), spp, 1))
        llvm_warm.append(ms.render("llvm_ad_rgb", xml, spp, seed=2 + k))
    mimg = mruns[0][0]
    mt, mwall = (float(np.median([r[i] for r in mruns])) for i in (1, 2))
    mcpu = float(np.median([r[3] / r[2] for r in mruns]))
    warm_t = float(np.median([r[1] for r in llvm_warm]))
    rows.append(dict(tool=mf.name, time=mt, wall=mwall, cpu=mcpu, img=mimg,
                     note=f"median of {EQ_RUNS} runs; process {mwall:.2f} s incl. loading"))
    if before:
        bt, bwall = (float(np.median([r[i] for r in bruns])) for i in (1, 2))
        rows.append(dict(tool=before.name, time=bt, wall=bwall, img=bruns[0][0],
                         cpu=float(np.median([r[3] / r[2] for r in bruns])),
                         note=f"median of {EQ_RUNS} runs; process {bwall:.2f} s incl. loading"))
    rows.append(dict(tool="Mitsuba llvm_ad_rgb, first call", time=llvm_first[1],
                     cpu=llvm_first[2] / llvm_first[1], img=llvm_first[0],
                     note=f"JIT compile (empty kernel cache); load {t_load:.2f} s"))
    rows.append(dict(tool="Mitsuba llvm_ad_rgb, warm", time=warm_t,
                     cpu=float(np.median([r[2] / r[1] for r in llvm_warm])), img=llvm_warm[0][0],
                     note=f"median of {EQ_RUNS} calls, kernels cached"))
    rows.append(dict(tool="Mitsuba scalar_rgb", time=scal[1], cpu=scal[2] / scal[1],
                     img=scal[0], note=f"load {t_load_s:.2f} s"))

    # The reference: two halves with disjoint seeds.
    log(f"forward: reference, Mitsuba llvm_ad_rgb {cfg['ref_spp']} spp ...")
    half = cfg["ref_spp"] // 2
    ref_a, ta, _ = ms.render("llvm_ad_rgb", xml, half, seed=101)
    ref_b, tb, _ = ms.render("llvm_ad_rgb", xml, half, seed=202)
    ref = 0.5 * (ref_a + ref_b)
    ref_noise2 = float(((ref_a - ref_b) ** 2)[off_light].mean() / 4.0)
    write_exr(ms.mi, os.path.join(d, "reference.exr"), ref)
    res["reference"] = dict(spp=cfg["ref_spp"], seconds=ta + tb, rmse=ref_noise2 ** 0.5)

    def rmse(img):
        e2 = float(((img - ref) ** 2)[off_light].mean()) - ref_noise2
        return max(e2, 0.0) ** 0.5

    def rmse_all(img):
        return float(((img - ref) ** 2).mean()) ** 0.5

    res["mean_radiance"] = float(ref[off_light].mean())
    res["equal_spp"] = [
        dict(tool=r["tool"], spp=spp, seconds=r["time"],
             samples_per_s=px * spp / r["time"], cpu_use=r["cpu"], rmse=rmse(r["img"]),
             rmse_all=rmse_all(r["img"]), note=r["note"]) for r in rows]

    # Equal time: spp from each tool's warm throughput.
    thr = {"matfit": px * spp / mt, "llvm": px * spp / warm_t, "scalar": px * spp / scal[1]}
    if before:
        thr["before"] = px * spp / bt
    eq_time = []
    longest = {}
    for b in cfg["budgets"]:
        log(f"forward: equal time ({b:g} s) ...")
        n = max(1, round(b * thr["matfit"] / px))
        img, t, wall, cpu = mf.render(scene, os.path.join(d, f"matfit_{b:g}s.pfm"), n, 7)
        eq_time.append(dict(budget=b, tool=mf.name, spp=n, seconds=t, rmse=rmse(img),
                            rmse_all=rmse_all(img), cpu_use=cpu / wall))
        longest["matfit"] = (img, n)
        if before:
            n = max(1, round(b * thr["before"] / px))
            img, t, wall, cpu = before.render(scene, os.path.join(d, f"before_{b:g}s.pfm"), n, 7)
            eq_time.append(dict(budget=b, tool=before.name, spp=n, seconds=t, rmse=rmse(img),
                                rmse_all=rmse_all(img), cpu_use=cpu / wall))
        n = max(1, round(b * thr["llvm"] / px))
        first = ms.render("llvm_ad_rgb", xml, n, seed=11)  # compiles if this spp is new
        img, t, cpu = ms.render("llvm_ad_rgb", xml, n, seed=12)
        eq_time.append(dict(budget=b, tool="Mitsuba llvm_ad_rgb", spp=n, seconds=t,
                            rmse=rmse(img), rmse_all=rmse_all(img), cpu_use=cpu / t,
                            first_call=first[1]))
        longest["mitsuba"] = (img, n)
        n = max(1, round(b * thr["scalar"] / px))
        img, t, cpu = ms.render("scalar_rgb", xml, n, seed=13)
        eq_time.append(dict(budget=b, tool="Mitsuba scalar_rgb", spp=n, seconds=t,
                            rmse=rmse(img), rmse_all=rmse_all(img), cpu_use=cpu / t))
    # Efficiency 1 / (RMSE^2 x time), and its ratio to Mitsuba llvm's at the same budget.
    for r in eq_time:
        r["efficiency"] = 1.0 / max(r["rmse"] ** 2 * r["seconds"], 1e-300)
    for r in eq_time:
        llvm = next(x for x in eq_time
                    if x["budget"] == r["budget"] and x["tool"] == "Mitsuba llvm_ad_rgb")
        r["vs_llvm"] = r["efficiency"] / llvm["efficiency"]
    res["equal_time"] = eq_time

    # Does matfit agree with the reference? Group means over eroded masks.
    agree = []
    mimg, n_mf = longest["matfit"]
    limg, n_ml = longest["mitsuba"]
    for g, mask in sorted(cc.eroded_masks(ids).items()):
        if g == light_id or mask.sum() < 50:
            continue
        a, b, c = mimg[mask].mean(0), ref[mask].mean(0), limg[mask].mean(0)
        agree.append(dict(group=group_names[g], pixels=int(mask.sum()),
                          matfit=a.tolist(), reference=b.tolist(),
                          rel=cc.rel_diff(a, b).tolist(), rel_mitsuba=cc.rel_diff(c, b).tolist()))
    res["agreement"] = dict(matfit_spp=n_mf, mitsuba_spp=n_ml, groups=agree)
    return res, ref


def run_rss(cmd, env=None):
    """Runs `cmd` like `run`; also returns its resource usage (os.wait4: ru_maxrss is its peak
    resident set size in KiB)."""
    with tempfile.TemporaryFile("w+") as fo, tempfile.TemporaryFile("w+") as fe:
        p = subprocess.Popen(cmd, stdout=fo, stderr=fe, text=True, env=env)
        _, status, ru = os.wait4(p.pid, 0)
        p.returncode = os.waitstatus_to_exitcode(status)
        fo.seek(0)
        fe.seek(0)
        out, err = fo.read(), fe.read()
    if p.returncode != 0:
        sys.exit(f"compare.py: {' '.join(cmd)} failed ({p.returncode}):\n{out}{err}")
    return subprocess.CompletedProcess(cmd, 0, out, err), ru


def forward_big(mf, ms, big, d):
    """Equal-spp throughput on office-large, all diffuse (BIG): matfit against Mitsuba llvm
    (warm), EQ_RUNS each taking turns, medians; loading (matfit: process wall time minus
    render time, i.e. PLY reading and the BVH build; Mitsuba: load_file); per-group means of
    the two renderers' images against the noise between two Mitsuba renders."""
    w, h = big["res"]
    spp = big["spp"]
    px = w * h
    os.makedirs(d, exist_ok=True)
    log(f"forward, big mesh: office-large (diffuse), {w}×{h}, {spp} spp ...")
    scene, triangles = cc.office_diffuse(d, w, h, big["triangles"])
    xml, ids, names = export_case(mf, d, scene)
    _, t_load = ms.scene("llvm_ad_rgb", xml)
    first = ms.render("llvm_ad_rgb", xml, spp, seed=1)
    env = dict(os.environ, MATFIT_LOG="info")
    mruns, warm, rss = [], [], []
    out = os.path.join(d, "matfit.pfm")
    for k in range(EQ_RUNS):
        t0 = time.perf_counter()
        r, ru = run_rss(mf.cmd("render", scene, "-o", out, "--spp", str(spp), "--seed", "1"),
                        env=env)
        wall = time.perf_counter() - t0
        t = next(float(l.split("rendered in")[1].split()[0])
                 for l in r.stderr.splitlines() if "rendered in" in l)
        mruns.append((t, wall))
        rss.append(ru.ru_maxrss / 1024.0)
        warm.append(ms.render("llvm_ad_rgb", xml, spp, seed=2 + k))
    mimg = cc.read_pfm(out).astype(np.float64)
    mt = float(np.median([t for t, _ in mruns]))
    mwall = float(np.median([x for _, x in mruns]))
    wt = float(np.median([x[1] for x in warm]))
    # Agreement: group means (eroded masks, >= 400 px) of matfit's image and the mean of
    # Mitsuba's warm renders; the noise is the largest such difference between two of Mitsuba's.
    mits = np.mean([x[0] for x in warm], axis=0)
    worst, noise, groups = 0.0, 0.0, 0
    for g, mask in cc.eroded_masks(ids).items():
        if mask.sum() < 400 or names[g].startswith("light"):
            continue
        groups += 1
        a, b = mimg[mask].mean(0), mits[mask].mean(0)
        worst = max(worst, float(np.abs(cc.rel_diff(a, b)).max()))
        n = cc.rel_diff(warm[0][0][mask].mean(0), warm[1][0][mask].mean(0))
        noise = max(noise, float(np.abs(n).max()))
    return dict(
        res=[w, h], spp=spp, triangles=triangles, groups=len(names),
        matfit=dict(seconds=mt, wall=mwall, load=mwall - mt, samples_per_s=px * spp / mt,
                    rss_mb=max(rss)),
        mitsuba=dict(seconds=wt, first_call=first[1], load=t_load,
                     samples_per_s=px * spp / wt),
        agreement=dict(groups=groups, worst=worst, mitsuba_noise=noise))


# ----------------------------------------------------------------------------------------------
# 2. inverse


def matfit_recover(mf, scene, photo, out, extra, truth, groups):
    """Runs `matfit recover`; returns the error curve [(t, err)], results, wall time."""
    shutil.rmtree(out, ignore_errors=True)
    t0 = time.perf_counter()
    # The photos come through the scene's camera: the film shift (cheap) registers them, as
    # when this benchmark's figures were recorded; the pose refinement would add its renders
    # to the start-up counted below.
    run(mf.cmd("recover", scene, photo, "-o", out, "--exposure", "1", "--film-shift", *extra))
    wall = time.perf_counter() - t0
    results = json.load(open(os.path.join(out, "results.json")))
    startup = max(0.0, wall - results["timing"]["total_s"])
    cur = {g: (np.full(3, 0.5), np.zeros(3)) for g in groups}
    curve = [(0.0, max_err(cur, truth, groups))]
    last_t = 0.0
    for line in open(os.path.join(out, "log.jsonl")):
        ln = json.loads(line)
        if ln["group"] in cur:
            cur[ln["group"]] = params_rhos(ln["params"])
        last_t = startup + ln["elapsed"]
        curve.append((last_t, max_err(cur, truth, groups)))
    final = {}
    for gr in results["groups"]:
        if gr["name"] in groups:
            final[gr["name"]] = dict(level=gr["level"], status=gr["status"],
                                     params=gr["params"])
    fin_cur = {g: params_rhos(final[g]["params"]) for g in groups}
    return dict(curve=curve, final=final, final_err=max_err(fin_cur, truth, groups),
                wall=wall, startup=startup, last_log_t=last_t,
                iterations=results.get("iterations"), total_s=results["timing"]["total_s"])


def reflectance_keys(params, group, objects):
    """The Mitsuba parameters holding a group's diffuse reflectance: the exporter writes one
    two-sided BSDF per group, named after it, which the group's shapes reference (older exports
    gave each shape its own BSDF, named after the shape)."""
    shared = f"{group}.brdf_0.reflectance.value"
    if shared in params:
        return [shared]
    keys = [f"{o}.bsdf.brdf_0.reflectance.value" for o in objects]
    missing = [k for k in keys if k not in params]
    if missing:
        sys.exit(f"compare.py: Mitsuba scene has neither {shared} nor {missing[0]}")
    return keys


class MitsubaFit:
    """One Mitsuba inverse-rendering run (prb + Adam), resumable: run_until(budget)."""

    def __init__(self, ms, xml, photo, objects, truth, groups, max_depth, lr, spp,
                 halflife=None, lr_min=None):
        mi, dr = ms.mi, ms.dr
        self.mi, self.dr = mi, dr
        self.lr0, self.spp, self.halflife, self.lr_min = lr, spp, halflife, lr_min
        self.truth, self.groups = truth, groups
        mi.set_variant("llvm_ad_rgb")
        mi.set_log_level(mi.LogLevel.Error)
        dr.set_thread_count(ms.threads)
        mi.file_resolver().prepend(os.path.dirname(xml))
        t0 = time.perf_counter()
        self.scene = mi.load_file(xml, optimize=False)
        self.params = mi.traverse(self.scene)
        self.ref = mi.TensorXf(np.asarray(photo, dtype=np.float32))
        self.integrator = mi.load_dict({"type": "prb", "max_depth": max_depth})
        self.keys = {g: reflectance_keys(self.params, g, objects[g]) for g in groups}
        self.load_s = time.perf_counter() - t0
        # Warm-up: two iterations, discarded (their extra time is the JIT compilation).
        self._reset()
        w = [self._iteration(10_000 + i) for i in range(2)]
        self.warmup = w
        self._reset()
        self.clock = self.load_s  # seconds charged to this run: loading + iterations
        self.it = 0
        self.curve = [(self.clock, self._err())]

    def _reset(self):
        mi = self.mi
        self.opt = mi.ad.Adam(lr=self.lr0)
        for g in self.groups:
            self.opt[g] = mi.Color3f(0.5)
        self._push()

    def _push(self):
        for g, ks in self.keys.items():
            for k in ks:
                self.params[k] = self.opt[g]
        self.params.update()

    def _iteration(self, seed):
        dr, mi = self.dr, self.mi
        t0 = time.perf_counter()
        img = mi.render(self.scene, self.params, integrator=self.integrator, spp=self.spp,
                        seed=seed)
        loss = dr.mean(dr.square(img - self.ref))
        dr.backward(loss)
        self.opt.step()
        for g in self.groups:
            self.opt[g] = dr.clip(self.opt[g], 0.0, 1.0)
        self._push()
        dr.eval(*[self.opt[g] for g in self.groups])
        dr.sync_thread()
        return time.perf_counter() - t0

    def _current(self):
        return {g: (np.array(self.opt[g], dtype=np.float64).ravel(), np.zeros(3))
                for g in self.groups}

    def _err(self):
        return max_err(self._current(), self.truth, self.groups)

    def run_until(self, budget):
        while self.clock < budget:
            if self.halflife:
                # Exponential decay of the learning rate, floored.
                lr = max(self.lr0 * 0.5 ** (self.it / self.halflife), self.lr_min)
                self.opt.set_learning_rate(lr)
            self.clock += self._iteration(self.it)
            self.it += 1
            self.curve.append((self.clock, self._err()))

    def tail_error(self):
        """Largest error over the last quarter of the run so far (the pilot's score)."""
        t_end = self.curve[-1][0]
        return max(e for t, e in self.curve if t >= 0.75 * t_end)

    def label(self):
        s = f"lr {self.lr0:g}"
        if self.halflife:
            s += f" → {self.lr_min:g} (half-life {self.halflife} it.)"
        return f"{s}, {self.spp} spp/it."

    def final(self):
        return {g: v[0].tolist() for g, v in self._current().items()}


# ----------------------------------------------------------------------------------------------
# plot (hand-written SVG: no plotting library in the venv)


def svg_plot(path, curves, thresholds, title):
    W, H, L, R, T, B = 760, 440, 70, 20, 40, 50
    tmin = min(max(t, 0.1) for _, _, c in curves for t, _ in c)
    tmax = max(t for _, _, c in curves for t, _ in c)
    tmin = 10 ** np.floor(np.log10(tmin))
    tmax = 10 ** np.ceil(np.log10(tmax))
    emin, emax = 1e-3, 1.0

    def X(t):
        return L + (np.log10(max(t, tmin)) - np.log10(tmin)) / (np.log10(tmax) - np.log10(tmin)) \
            * (W - L - R)

    def Y(e):
        e = min(max(e, emin), emax)
        return T + (np.log10(emax) - np.log10(e)) / (np.log10(emax) - np.log10(emin)) * (H - T - B)

    o = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" '
         f'font-family="sans-serif" font-size="12">',
         f'<rect width="{W}" height="{H}" fill="white"/>',
         f'<text x="{W / 2}" y="20" text-anchor="middle" font-size="14">{title}</text>']
    k = np.log10(tmin)
    while k <= np.log10(tmax) + 1e-9:
        t = 10 ** k
        o.append(f'<line x1="{X(t):.1f}" y1="{T}" x2="{X(t):.1f}" y2="{H - B}" stroke="#ddd"/>')
        o.append(f'<text x="{X(t):.1f}" y="{H - B + 16}" text-anchor="middle">{t:g}</text>')
        k += 1
    for e in (1e-3, 1e-2, 1e-1, 1.0):
        o.append(f'<line x1="{L}" y1="{Y(e):.1f}" x2="{W - R}" y2="{Y(e):.1f}" stroke="#ddd"/>')
        o.append(f'<text x="{L - 6}" y="{Y(e) + 4:.1f}" text-anchor="end">{e:g}</text>')
    for thr in thresholds:
        o.append(f'<line x1="{L}" y1="{Y(thr):.1f}" x2="{W - R}" y2="{Y(thr):.1f}" '
                 f'stroke="#999" stroke-dasharray="4,4"/>')
        o.append(f'<text x="{W - R - 4}" y="{Y(thr) - 4:.1f}" text-anchor="end" '
                 f'fill="#666">{thr:g}</text>')
    o.append(f'<rect x="{L}" y="{T}" width="{W - L - R}" height="{H - T - B}" fill="none" '
             f'stroke="black"/>')
    o.append(f'<text x="{(L + W - R) / 2}" y="{H - 12}" text-anchor="middle">time (s, log)'
             f'</text>')
    o.append(f'<text x="16" y="{(T + H - B) / 2}" text-anchor="middle" '
             f'transform="rotate(-90 16 {(T + H - B) / 2})">max |error| over all channels (log)'
             f'</text>')
    for i, (label, colour, c) in enumerate(curves):
        pts = []
        for j, (t, e) in enumerate(c):
            if j > 0:
                pts.append(f"{X(t):.1f},{Y(c[j - 1][1]):.1f}")  # step: error holds until t
            pts.append(f"{X(t):.1f},{Y(e):.1f}")
        o.append(f'<polyline points="{" ".join(pts)}" fill="none" stroke="{colour}" '
                 f'stroke-width="1.5"/>')
        ly = H - B - 10 - 16 * (len(curves) - 1 - i)  # bottom left: early and accurate is empty
        o.append(f'<line x1="{L + 10}" y1="{ly - 4}" x2="{L + 34}" y2="{ly - 4}" '
                 f'stroke="{colour}" stroke-width="2"/>')
        o.append(f'<text x="{L + 40}" y="{ly}">{label}</text>')
    o.append("</svg>")
    with open(path, "w") as f:
        f.write("\n".join(o) + "\n")


# ----------------------------------------------------------------------------------------------
# report


def f3(v):
    return ", ".join(f"{x:.3f}" for x in v)


def markdown(meta, fw, inv, cross, cfg, svg_name):
    w, h = fw["res"]
    L = []
    A = L.append
    A("# matfit vs Mitsuba 3: forward rendering, inverse rendering, cross-renderer accuracy\n")
    if meta["provisional"]:
        A(f"**Provisional**: {meta['provisional']}\n")
    if inv is None:
        L[0] = "# matfit vs Mitsuba 3: forward rendering\n"
    A("Made by one command (what each number means: [bench/README.md](README.md)):\n")
    A(f"```sh\n{meta['command']}\n```\n")
    A(f"- date: {meta['date']}")
    A(f"- machine: {meta['machine']}; load average {meta['load_start']} at the start, "
      f"{meta['load_end']} at the end (`nproc` = {meta['nproc']})")
    A(f"- {meta['matfit_version']} (git {meta['git']}), `--threads {meta['threads']}`; "
      f"Mitsuba {meta['mitsuba']}, Dr.Jit {meta['drjit']} (`dr.set_thread_count("
      f"{meta['threads']})`), numpy {meta['numpy']}, Python {meta['python']}")
    if meta.get("scene", "figure6") == "glossy":
        A(f"- scene: scenes/glossy with its Ward sphere as the Beckmann lobe `matfit export "
          f"mitsuba` fits to it (`{GLOSSY_SPHERE}`), {w}×{h}, max_depth 8 in both renderers; "
          f"total run time {meta['total_s'] / 60:.1f} min")
    else:
        A(f"- scene: scenes/figure6 with a diffuse floor ρd = ({f3(FLOOR_RHO)}), {w}×{h}, "
          f"max_depth 8 in both renderers; total run time {meta['total_s'] / 60:.1f} min")
    if meta.get("before"):
        A(f"- 'matfit before': {meta['before']}, measured in the same run, taking turns")
    A("")

    A("## 1. Forward rendering\n")
    A(f"Reference: Mitsuba `llvm_ad_rgb` at {fw['reference']['spp']} spp "
      f"({fw['reference']['seconds']:.0f} s; its own noise, RMSE {fw['reference']['rmse']:.2e}, "
      f"is subtracted from every RMSE below). RMSE over all pixels but the light and a 2-pixel "
      f"band around it (mean radiance there {fw['mean_radiance']:.3f}); 'all px' includes the "
      f"light's edges. CPU = CPU time / wall time (2.0 = both cores busy).\n")
    A(f"**Equal spp** ({fw['equal_spp'][0]['spp']} spp, {w}×{h}):\n")
    A("| renderer | render time | samples/s | CPU | RMSE | RMSE, all px | |")
    A("|---|---:|---:|---:|---:|---:|---|")
    for r in fw["equal_spp"]:
        A(f"| {r['tool']} | {r['seconds']:.2f} s | {r['samples_per_s'] / 1e6:.2f} M | "
          f"{r['cpu_use']:.2f} | {r['rmse']:.4f} | {r['rmse_all']:.4f} | {r['note']} |")
    A("")
    A("**Equal time** (spp chosen from each renderer's equal-spp throughput; Mitsuba llvm "
      "timed on a second call at that spp, its first call in brackets):\n")
    A("| budget | renderer | spp | time | CPU | RMSE | RMSE, all px | efficiency | vs llvm |")
    A("|---:|---|---:|---:|---:|---:|---:|---:|---:|")
    for r in fw["equal_time"]:
        t = f"{r['seconds']:.2f} s"
        if "first_call" in r:
            t += f" ({r['first_call']:.2f} s)"
        eff = (f"{r['efficiency']:.0f} | {r['vs_llvm']:.2f}×" if "efficiency" in r else " | ")
        A(f"| {r['budget']:g} s | {r['tool']} | {r['spp']} | {t} | {r['cpu_use']:.2f} | "
          f"{r['rmse']:.4f} | {r['rmse_all']:.4f} | {eff} |")
    A("")
    ag = fw["agreement"]
    worst = max(max(abs(x) for x in g["rel"]) for g in ag["groups"])
    worst_m = max(max(abs(x) for x in g["rel_mitsuba"]) for g in ag["groups"])
    A(f"**Do matfit and the reference agree?** Group means (masks eroded by 2 px) of matfit's "
      f"{ag['matfit_spp']}-spp equal-time render against the reference: largest |rel. diff| "
      f"{worst:.2%} (Mitsuba's own {ag['mitsuba_spp']}-spp render: {worst_m:.2%}, i.e. the "
      f"noise at that spp). `bench/crosscheck.py` checks this at 1% with error bars.\n")
    A("| group | pixels | matfit | reference | rel. diff | Mitsuba low-spp rel. diff |")
    A("|---|---:|---|---|---|---|")
    for g in ag["groups"]:
        A(f"| {g['group']} | {g['pixels']} | {f3(g['matfit'])} | {f3(g['reference'])} | "
          f"{', '.join(f'{x:+.2%}' for x in g['rel'])} | "
          f"{', '.join(f'{x:+.2%}' for x in g['rel_mitsuba'])} |")
    A("")

    if "big" in fw:
        b = fw["big"]
        bw, bh = b["res"]
        m, x = b["matfit"], b["mitsuba"]
        A(f"**On a big mesh**: scenes/office-large made all diffuse (`make_scene.py --diffuse`), "
          f"{b['triangles']:,} triangles, {b['groups']} groups, {bw}×{bh}, {b['spp']} spp, "
          f"max_depth 8 (equal spp; medians of {EQ_RUNS} runs each, taking turns). Loading is "
          f"matfit's process wall time minus its render time (reading the PLY meshes, building "
          f"the BVH) and Mitsuba's `load_file`.\n")
        A("| renderer | loading | render time | samples/s | peak RSS | |")
        A("|---|---:|---:|---:|---:|---|")
        A(f"| matfit | {m['load']:.2f} s | {m['seconds']:.2f} s | "
          f"{m['samples_per_s'] / 1e6:.2f} M | {m['rss_mb']:.0f} MB | process |")
        A(f"| Mitsuba llvm_ad_rgb, warm | {x['load']:.2f} s | {x['seconds']:.2f} s | "
          f"{x['samples_per_s'] / 1e6:.2f} M | | first call {x['first_call']:.2f} s |")
        A("")
        ag = b["agreement"]
        A(f"matfit / Mitsuba throughput: **{m['samples_per_s'] / x['samples_per_s']:.2f}×**. "
          f"Group means (masks eroded by 2 px, the {ag['groups']} groups with ≥ 400 such "
          f"pixels) of matfit's image against Mitsuba's {EQ_RUNS} renders averaged: largest "
          f"|rel. diff| {ag['worst']:.2%}; between two of Mitsuba's own renders "
          f"{ag['mitsuba_noise']:.2%} (the noise at {b['spp']} spp).\n")

    if inv is None:
        A("## Goals\n")
        for g in meta["goals"]:
            A(f"- {g}")
        A("")
        return "\n".join(L)

    A("## 2. Inverse rendering\n")
    A(f"Photo: the reference image above. Unknowns: ρd (RGB) of the {len(inv['groups'])} "
      f"visible groups ({', '.join(inv['groups'])}), all starting from 0.5; the unseen "
      f"ceiling keeps its ρd 1, its truth, in both tools (matfit `--white-unseen`: by default "
      f"matfit estimates it, one more unknown than Mitsuba has) and "
      f"the light is known. Error = max |recovered − true| over all channels of all these "
      f"groups. Times: matfit from process start; Mitsuba from scene loading, without JIT "
      f"compilation (its warm-up iterations took {inv['mitsuba_warmup']}). "
      f"'Reached' = stays at or below the threshold to the end of the run. Mitsuba: each "
      f"configuration ran a {inv['pilot']:g}-s pilot; the one with the lowest error over the "
      f"last quarter of its pilot was continued to {inv['long_budget']:.0f} s (20× matfit's "
      f"time to 0.01, within bounds).\n")
    A("| tool | configuration | iterations (s each) | ≤ 0.05 | ≤ 0.02 | ≤ 0.01 | final max error "
      "| run |")
    A("|---|---|---:|---|---|---|---:|---:|")
    m = inv["matfit"]
    A(f"| matfit `recover` | defaults{' ' + ' '.join(cfg['recover_args']) if cfg['recover_args'] else ''} | "
      f"{m['iterations']} ({(m['last_log_t'] - m['startup']) / max(m['iterations'], 1):.2f} s) | "
      + " | ".join(fmt_t(m['reach'][str(t)]) for t in THRESHOLDS) +
      f" | {m['final_err']:.4f} | {m['wall']:.1f} s (parameters final at "
      f"{m['last_log_t']:.1f} s) |")
    for r in inv["mitsuba"]:
        A(f"| Mitsuba prb + Adam{' (best, continued)' if r['best'] else ''} | {r['label']} | "
          f"{r['iterations']} ({r['per_it']:.2f} s) | " + " | ".join(fmt_t(r['reach'][str(t)],
                                                     f" in {r['clock']:.0f} s")
                                               for t in THRESHOLDS) +
          f" | {r['final_err']:.4f} | {r['clock']:.0f} s |")
    A("")
    A(f"![max error vs time]({svg_name})\n")
    A(f"{inv['ratio_text']}\n")

    A("## 3. Cross-renderer accuracy (matfit recovers from Mitsuba's photos)\n")
    for case in cross:
        A(f"**{case['name']}** (photo: Mitsuba `llvm_ad_rgb`, {case['spp']} spp, {w}×{h}; "
          f"matfit {case['wall']:.1f} s): largest error {case['max_err']:.4f}\n")
        A("| group | true | recovered level | ρd R, G, B (true → recovered) | ρs (true → "
          "recovered) | max abs error |")
        A("|---|---|---|---|---|---:|")
        for r in case["rows"]:
            A(f"| {r['group']} | {r['true_model']} | {r['level']} | "
              f"{f3(r['true_d'])} → {f3(r['rec_d'])} | {f3(r['true_s'])} → {f3(r['rec_s'])} | "
              f"{r['err']:.4f} |")
        A("")

    A("## Goals\n")
    for g in meta["goals"]:
        A(f"- {g}")
    A("")
    return "\n".join(L)


# ----------------------------------------------------------------------------------------------


def export_case(mf, d, scene):
    """Exports SCENE to Mitsuba under D (stopping on any approximation the exporter warns of)
    and renders its group ids: (the XML's path, per-pixel group ids, group names)."""
    xml_dir = os.path.join(d, "mitsuba")
    r = run([mf.exe, "export", "mitsuba", scene, "-o", xml_dir])
    # "note:" lines (e.g. writing over an earlier run's export) are not approximations.
    warned = [l for l in r.stderr.splitlines() if l.strip() and not l.startswith("note:")]
    if warned:
        sys.exit("compare.py: matfit export warned:\n" + "\n".join(warned))
    run(mf.cmd("render", scene, "--aov", "group", "-o", os.path.join(d, "ids.pfm")))
    ids = np.rint(cc.read_pfm(os.path.join(d, "ids.pfm"))[..., 0]).astype(int)
    return os.path.join(xml_dir, "scene.xml"), ids, cc.group_names(mf.exe, scene)


def prepare_case(mf, d, floor, res):
    os.makedirs(d, exist_ok=True)
    scene = cc.figure6_variant(d, floor, *res)
    xml, ids, names = export_case(mf, d, scene)
    return scene, xml, ids, names


def prepare_glossy(mf, d, res):
    """scenes/glossy with its Ward sphere as GLOSSY_SPHERE, at RES, exported under D."""
    os.makedirs(d, exist_ok=True)
    scene = cc.scene_variant("glossy", d, GLOSSY_SPHERE, *res)
    xml, ids, names = export_case(mf, d, scene)
    return scene, xml, ids, names


def visible_groups(ids, names, truth):
    return [names[g] for g in range(len(names))
            if names[g] in truth and int((ids == g).sum()) >= 50]


def cross_rows(rec, truth, groups):
    rows = []
    for g in groups:
        model, td, ts = truth[g]
        fin = rec["final"][g]
        rd, rs = params_rhos(fin["params"])
        err = max(float(np.abs(rd - td).max()), float(np.abs(rs - ts).max()))
        rows.append(dict(group=g, true_model=model, level=fin["level"], true_d=td.tolist(),
                         rec_d=rd.tolist(), true_s=ts.tolist(), rec_s=rs.tolist(), err=err))
    return rows


def measure(args, cfg, out):
    """Runs every measurement; writes OUT/{forward,inverse,cross,meta}.json and the plot."""
    # An empty kernel cache, so that Mitsuba's first llvm call shows the JIT compilation.
    cache = os.path.join(out, "drjit-cache")
    shutil.rmtree(cache, ignore_errors=True)
    os.makedirs(cache)
    os.environ["DRJIT_CACHE_DIR"] = cache
    if not os.environ.get("DRJIT_LIBLLVM_PATH"):
        print("warning: DRJIT_LIBLLVM_PATH unset; source bench/mitsuba_env.sh", file=sys.stderr)

    t_all = time.perf_counter()
    load_start = "%.2f %.2f %.2f" % os.getloadavg()
    mf = Matfit(cc.find_matfit(args.matfit), args.threads)
    before = (Matfit(os.path.abspath(args.before), args.threads, "matfit before")
              if args.before else None)
    ms = Mitsuba(args.threads)
    log(f"{'quick' if args.quick else 'full'} mode, {args.threads} threads, matfit {mf.exe}, "
        f"out {out}")
    for name in ("inverse.json", "cross.json"):
        if os.path.exists(os.path.join(out, name)):
            os.remove(os.path.join(out, name))

    # Scenes.
    if args.scene == "glossy":
        dd = os.path.join(out, "glossy")
        scene, xml, ids, names = prepare_glossy(mf, dd, cfg["res"])
    else:
        floor_d = "{ type = \"diffuse\", rho_d = [%g, %g, %g] }" % FLOOR_RHO
        dd = os.path.join(out, "diffuse")
        scene, xml, ids, names = prepare_case(mf, dd, floor_d, cfg["res"])
    light_id = names.index("light")

    # 1. forward
    fw, ref = forward(mf, ms, cfg, dd, scene, xml, ids, light_id, names, before)
    if not args.forward_only:
        fw["big"] = forward_big(mf, ms, BIG["quick" if args.quick else "full"],
                                os.path.join(out, "office"))
    json.dump(fw, open(os.path.join(out, "forward.json"), "w"), indent=1)
    if args.forward_only:
        write_meta(args, cfg, out, mf, ms, load_start, t_all)
        return
    truth = scene_truth(scene)
    objects = group_objects(scene)
    groups = visible_groups(ids, names, truth)
    photo = os.path.join(dd, "reference.exr")

    # 2. inverse: matfit
    log("inverse: matfit recover ...")
    mrec = matfit_recover(mf, scene, photo, os.path.join(dd, "recover"), cfg["recover_args"],
                          truth, groups)
    t01 = reach_times(mrec["curve"], 0.01)[0]
    log(f"  matfit: final error {mrec['final_err']:.4f}, wall {mrec['wall']:.1f} s, "
        f"0.01 reached at {t01}")

    # 2. inverse: Mitsuba pilots, then the best continued.
    fits = []
    for c in cfg["configs"]:
        f = MitsubaFit(ms, xml, ref, objects, truth, groups, 8, **c)
        log(f"inverse: Mitsuba prb + Adam, {f.label()}, pilot {cfg['pilot']:g} s ...")
        f.run_until(cfg["pilot"])
        log(f"  {f.label()}: {f.it} iterations, error {f.curve[-1][1]:.4f}, "
            f"last-quarter max {f.tail_error():.4f}")
        fits.append(f)
    best = min(fits, key=lambda f: f.tail_error())
    long_budget = cfg["long_max"] if t01 is None else min(cfg["long_max"], 20.0 * t01)
    long_budget = max(long_budget, cfg["long_min"], cfg["pilot"])
    log(f"inverse: continuing {best.label()} to {long_budget:.0f} s ...")
    best.run_until(long_budget)
    mits = [dict(label=f.label(), best=f is best, iterations=f.it, clock=f.clock,
                 curve=f.curve, final=f.final(), final_err=f.curve[-1][1], warmup=f.warmup,
                 per_it=(f.clock - f.load_s) / max(f.it, 1)) for f in fits]
    inv = dict(groups=groups, matfit=mrec, mitsuba=mits, pilot=cfg["pilot"],
               long_budget=long_budget)
    json.dump(inv, open(os.path.join(out, "inverse.json"), "w"), indent=1)

    # 3. cross-renderer: diffuse (the run above), then the mirror floor.
    cross = [dict(name="Diffuse floor", spp=cfg["ref_spp"], wall=mrec["wall"],
                  rows=cross_rows(mrec, truth, groups))]
    log(f"cross: mirror floor, Mitsuba photo {cfg['mirror_spp']} spp ...")
    md_ = os.path.join(out, "mirror")
    floor_m = f"{{ type = \"mirror\", rho_s = {MIRROR_RHO} }}"
    mscene, mxml, mids, mnames = prepare_case(mf, md_, floor_m, cfg["res"])
    mtruth = scene_truth(mscene)
    mgroups = visible_groups(mids, mnames, mtruth)
    mphoto_img, t_mp, _ = ms.render("llvm_ad_rgb", mxml, cfg["mirror_spp"], seed=303)
    mphoto = os.path.join(md_, "photo.exr")
    write_exr(ms.mi, mphoto, mphoto_img)
    log("cross: matfit recover (mirror floor) ...")
    mmrec = matfit_recover(mf, mscene, mphoto, os.path.join(md_, "recover"),
                           cfg["recover_args"], mtruth, mgroups)
    cross.append(dict(name=f"Mirror floor (ρs {MIRROR_RHO})", spp=cfg["mirror_spp"],
                      wall=mmrec["wall"], rows=cross_rows(mmrec, mtruth, mgroups)))
    json.dump(cross, open(os.path.join(out, "cross.json"), "w"), indent=1)
    write_meta(args, cfg, out, mf, ms, load_start, t_all)


def write_meta(args, cfg, out, mf, ms, load_start, t_all):
    """OUT/meta.json: the machine, the versions, the command, the run's load and time."""
    git = run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"]).stdout.strip()
    dirty = run(["git", "-C", ROOT, "status", "--porcelain", "--untracked-files=no"]).stdout
    meta = dict(
        quick=args.quick, res=list(cfg["res"]), scene=args.scene,
        before=os.path.abspath(args.before) if args.before else None, recover_args=cfg["recover_args"],
        provisional=args.provisional, command=command_line(args),
        date=datetime.datetime.now().astimezone().strftime("%Y-%m-%d %H:%M %Z"),
        machine=cc.machine(), nproc=os.cpu_count(), load_start=load_start,
        load_end="%.2f %.2f %.2f" % os.getloadavg(),
        matfit_version=run([mf.exe, "--version"]).stdout.strip(),
        git=git + (" + uncommitted changes" if dirty.strip() else ""), threads=args.threads,
        mitsuba=ms.mi.__version__, drjit=ms.dr.__version__, numpy=np.__version__,
        python=platform.python_version(), total_s=time.perf_counter() - t_all)
    json.dump(meta, open(os.path.join(out, "meta.json"), "w"), indent=1)


def command_line(args):
    """The command to quote in the report (run.sh's options, not the note)."""
    c = "bash bench/run.sh"
    if args.quick:
        c += " --quick"
    if args.threads != (os.cpu_count() or 2):
        c += f" --threads {args.threads}"
    if args.scene != "figure6":
        c += f" --scene {args.scene}"
    elif args.forward_only:
        c += " --forward-only"
    if args.before:
        c += " --before BINARY"
    return c


def forward_goals(fw):
    """The goals part 1 checks: equal-spp throughput (issues 7 and 24) and equal-time
    efficiency (issue 79: at least 2x Mitsuba llvm_ad_rgb's at every budget)."""
    eq = {r["tool"]: r for r in fw["equal_spp"]}
    mf_sps = eq["matfit"]["samples_per_s"]
    ll_sps = eq["Mitsuba llvm_ad_rgb, warm"]["samples_per_s"]
    goals = []
    ok = mf_sps >= ll_sps
    goals.append(f"Forward throughput ≥ Mitsuba llvm_ad_rgb: **{'met' if ok else 'not met'}** — "
                 f"matfit {mf_sps / 1e6:.2f} M samples/s vs {ll_sps / 1e6:.2f} M "
                 f"({mf_sps / ll_sps:.2f}×"
                 + ("" if ok else f"; matfit must become {ll_sps / mf_sps:.1f}× faster") + ").")
    ok = mf_sps >= 1.3 * ll_sps
    goals.append(f"Forward throughput ≥ 1.3× Mitsuba llvm_ad_rgb (issue 24): "
                 f"**{'met' if ok else 'not met'}** — {mf_sps / ll_sps:.2f}×"
                 + ("" if ok else f"; matfit must become {1.3 * ll_sps / mf_sps:.2f}× faster")
                 + ".")
    if "big" in fw:
        b = fw["big"]
        r = b["matfit"]["samples_per_s"] / b["mitsuba"]["samples_per_s"]
        goals.append(f"The same on the big mesh (office-large, diffuse, {b['triangles']:,} "
                     f"triangles): **{'met' if r >= 1.3 else 'not met'}** — {r:.2f}×"
                     + ("" if r >= 1.3 else f"; matfit must become {1.3 / r:.2f}× faster")
                     + ".")
    effs = [r for r in fw["equal_time"] if r["tool"] == "matfit" and "vs_llvm" in r]
    if effs:
        ok = all(r["vs_llvm"] >= 2.0 for r in effs)
        goals.append("Forward efficiency 1 / (RMSE² × time) ≥ 2× Mitsuba llvm_ad_rgb's (issue "
                     f"79): **{'met' if ok else 'not met'}** — "
                     + ", ".join(f"{r['vs_llvm']:.2f}× at {r['budget']:g} s" for r in effs) + ".")
    return goals


def report(out, md_path, provisional=None):
    """Derived figures, goals, plot and Markdown from OUT/*.json."""
    fw = json.load(open(os.path.join(out, "forward.json")))
    meta = json.load(open(os.path.join(out, "meta.json")))
    if provisional is not None:
        meta["provisional"] = provisional
    if not os.path.exists(os.path.join(out, "inverse.json")):
        # Part 1 alone (--forward-only, --scene glossy).
        meta["goals"] = forward_goals(fw)
        text = markdown(meta, fw, None, None, meta, None)
        with open(md_path, "w") as f:
            f.write(text)
        return text
    inv = json.load(open(os.path.join(out, "inverse.json")))
    cross = json.load(open(os.path.join(out, "cross.json")))
    mrec = inv["matfit"]
    mrec["reach"] = {str(t): reach_times(mrec["curve"], t) for t in THRESHOLDS}
    for m in inv["mitsuba"]:
        m["reach"] = {str(t): reach_times(m["curve"], t) for t in THRESHOLDS}
    for c in cross:
        c["max_err"] = max(r["err"] for r in c["rows"])

    # Time to 0.01: matfit against the fastest Mitsuba configuration (held to the end of its
    # run; a pilot's run is shorter, which only favours Mitsuba).
    t01, t01_first = mrec["reach"]["0.01"]
    held = [(m["reach"]["0.01"][0], m) for m in inv["mitsuba"] if m["reach"]["0.01"][0]]
    first = [(m["reach"]["0.01"][1], m) for m in inv["mitsuba"] if m["reach"]["0.01"][1]]
    longest = max(m["clock"] for m in inv["mitsuba"])
    ratio = None
    if t01 is None:
        text = "matfit did not reach 0.01."
    elif not held:
        text = (f"Time to 0.01: matfit {t01:.1f} s; no Mitsuba configuration held it, the longest "
                f"run lasting {longest:.0f} s: more than {longest / t01:.0f}× longer.")
    else:
        mt, m = min(held, key=lambda x: x[0])
        ratio = mt / t01
        text = (f"Time to 0.01 (held to the end of the run): matfit {t01:.1f} s, Mitsuba "
                f"{mt:.1f} s ({m['label']}): **{ratio:.1f}×** longer.")
        if first and t01_first:
            mf_, m2 = min(first, key=lambda x: x[0])
            text += (f" First touch of 0.01: matfit {t01_first:.1f} s, Mitsuba {mf_:.1f} s "
                     f"({m2['label']}): {mf_ / t01_first:.1f}×.")
    inv["ratio_text"] = text
    inv["mitsuba_warmup"] = (f"{inv['mitsuba'][0]['warmup'][0]:.2f} s and "
                             f"{inv['mitsuba'][0]['warmup'][1]:.2f} s in the first configuration, "
                             f"against {inv['mitsuba'][0]['per_it']:.2f} s for a timed one")

    goals = forward_goals(fw)
    if ratio is not None:
        goals.append(f"Inverse time to 0.01 ≥ 20× shorter than Mitsuba's: "
                     f"**{'met' if ratio >= 20 else 'not met'}** — {ratio:.1f}×"
                     + ("" if ratio >= 20 else f", {20 / ratio:.1f}× short of the goal") + ".")
    elif t01 is not None:
        lower = longest / t01
        goals.append(f"Inverse time to 0.01 ≥ 20× shorter than Mitsuba's: "
                     f"**{'met' if lower >= 20 else 'not shown'}** — Mitsuba did not hold 0.01 "
                     f"within {lower:.0f}× matfit's time.")
    else:
        goals.append("Inverse time to 0.01 ≥ 20× shorter: **not met** — matfit did not reach "
                     f"0.01 (final error {mrec['final_err']:.4f}).")
    worst = max(c["max_err"] for c in cross)
    goals.append(f"Cross-renderer ρ within 0.01: **{'met' if worst <= 0.01 else 'not met'}** — "
                 + "; ".join(f"{c['name'].lower()}: {c['max_err']:.4f}" for c in cross) + ".")
    meta["goals"] = goals

    colours = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b"]
    curves = [("matfit recover", "black", mrec["curve"])]
    for i, m in enumerate(inv["mitsuba"]):
        curves.append((f"Mitsuba {m['label']}", colours[i % len(colours)], m["curve"]))
    svg_name = "convergence-quick.svg" if meta["quick"] else "convergence.svg"
    svg = os.path.join(os.path.dirname(os.path.abspath(md_path)), svg_name)
    w, h = meta["res"]
    svg_plot(svg, curves, THRESHOLDS, f"figure6 (diffuse floor), {w}×{h}: max |ρ error| vs time")
    text = markdown(meta, fw, inv, cross, meta, svg_name)
    with open(md_path, "w") as f:
        f.write(text)
    return text


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="low resolution/spp/time (development)")
    ap.add_argument("--matfit", help="matfit binary (default: $MATFIT, $CARGO_TARGET_DIR)")
    ap.add_argument("--threads", type=int, default=os.cpu_count() or 2)
    ap.add_argument("--out", help="work folder (default bench/out/full or bench/out/quick)")
    ap.add_argument("--md", help="Markdown report (default bench/RESULTS.md; --quick: "
                                 "OUT/RESULTS.md)")
    ap.add_argument("--provisional", default=None,
                    help="a note printed at the top of the report (e.g. 'loaded machine')")
    ap.add_argument("--scene", choices=["figure6", "glossy"], default="figure6",
                    help="glossy: part 1 alone, on scenes/glossy (the docstring)")
    ap.add_argument("--forward-only", action="store_true", help="part 1 alone")
    ap.add_argument("--before", metavar="PATH",
                    help="another matfit binary to measure beside the first in part 1")
    ap.add_argument("--report-only", action="store_true",
                    help="measure nothing: rewrite the report from OUT/*.json")
    args = ap.parse_args()
    args.forward_only |= args.scene == "glossy"

    mode = "quick" if args.quick else "full"
    cfg = dict(MODES[mode])
    if args.scene == "glossy":
        cfg["res"] = GLOSSY_RES[mode]
    sub = mode if args.scene == "figure6" and not args.forward_only else f"{mode}-{args.scene}"
    out = os.path.abspath(args.out or os.path.join(HERE, "out", sub))
    md_path = args.md or (os.path.join(out, "RESULTS.md") if args.quick or args.forward_only
                          else os.path.join(HERE, "RESULTS.md"))
    os.makedirs(out, exist_ok=True)
    if not args.report_only:
        args.provisional = args.provisional or ""
        measure(args, cfg, out)
    text = report(out, md_path, args.provisional)
    print(text)
    log(f"wrote {md_path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
