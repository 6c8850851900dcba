#!/usr/bin/env python3
"""The acceptance figures of the "decisions" issue: Mitsuba 3 renders the photo, matfit recovers
it blind for several seeds, and each recovery is scored against the truth.

    bash bench/setup_mitsuba.sh && source bench/mitsuba_env.sh
    cargo build --release
    python bench/decisions.py [SCENE ...] [--seeds 5] [--scale 1.0] [--photo-spp 256]
        [--novel-spp 128] [--out bench/out/decisions] [--md FILE] [--recover-args "..."]

SCENE: interior, measured (both written by scenes/interior/generate.py), figure6, poster (the
bundled scenes, a control); default all four. A quick run (a few minutes a scene):

    python bench/decisions.py interior --seeds 1 --scale 0.5 --photo-spp 64 --novel-spp 32

Per scene:
  * the photo: Mitsuba (llvm_ad_rgb, box filter) renders the scene's true BSDFs at the photo's
    camera (--photo-spp, seed 1) -- for interior/measured the XML generate.py assembles
    (matfit's export with every group's BSDF replaced by the true one), for figure6/poster
    matfit's export of the scene as it is (figure6's Ward floor and poster's varnished desk
    become the export's microfacet stand-in: the photo is Mitsuba's, the truth table matfit's);
  * the novel view: Mitsuba renders the novel camera twice (--novel-spp, seeds 1 and 2); the
    noise floor is the whole-image L1 between the two;
  * `matfit recover scene.toml photo.pfm -o OUT --seed S` for S in 1..--seeds (default options
    otherwise: pose refinement, every level; --recover-args adds options), timed;
  * (a) novel-view L1: `matfit render OUT/recovered.toml --look-from/--look-at/--fov` (the novel
    camera, --novel-spp) against Mitsuba's seed-1 novel render, Σ|a − b| / Σ b over all pixels
    and channels, in %, beside the noise floor;
  * (b) per textured group (a truth texture), the PSNR of the recovered diffuse reflectance
    against the true one, per photo pixel of the group (matfit's group index buffer, eroded by
    1 px): each side rendered with only that group's objects, its varnish removed, under a
    uniform white [stray_light] of radiance 1, so a pixel's value is its ρd (peak 1); "flat"
    is the PSNR of the truth's own mean colour (what a uniform answer scores). "PSNR*"
    first fits one gain per channel (a textured coat's transmission scales the base: the
    truth of a textured roughplastic is its base under the coat, not the albedo matfit sees);
  * (c) each group's level per seed, and whether at least 4 of 5 seeds (80%) agree;
  * (d) ±2σ coverage: over every parameter channel with a truth value (truth.json; for the
    bundled scenes the scene file's materials), the share with |estimate − truth| ≤ 2σ (σ from
    results.json); σ null ("not determined") and parameters the recovered model lacks are
    counted apart and left out of the share. That compares a diffuse fit's ρd with a
    plastic's base as if they were the same quantity; two more columns do not: "truth's
    level" scores only the groups recovered at their truth's level, and "albedo" scores every
    uniform group's directional albedo at 0° and 60° (results.json's `albedo`, with its 1σ)
    against the true BSDF's (truth.json, from Mitsuba: `generate.py --albedos-only DIR` adds
    it to an older folder) -- the quantity every model has, matfit's or not;
  * (e) the recovery's wall time (and results.json's timing);
  * (f) each group's points of the novel view's L1 (its pixels in the novel camera's group
    buffer; they add up to (a)), where any seed gives it 0.1 or more.
Prints a markdown table per scene and writes it to --md (default OUT/DECISIONS.md).
"""
import argparse
import datetime
import json
import math
import os
import platform
import re
import shlex
import shutil
import subprocess
import sys
import time
import tomllib

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.normpath(os.path.join(HERE, ".."))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(ROOT, "scenes", "interior"))
from crosscheck import find_matfit, read_pfm  # noqa: E402
import generate  # noqa: E402

NOVEL = {  # novel cameras of the bundled scenes (figure6's is bench/nonward.py's)
    "figure6": {"eye": [1.5, 1.2, -1.2], "target": [-0.4, 0.5, -4.4], "fov": 40.0},
    "poster": {"eye": [1.0, 1.3, -1.9], "target": [-0.6, 0.9, -5.0], "fov": 45.0},
}


def write_pfm(path, img):
    img = np.ascontiguousarray(img[::-1].astype("<f4"))
    h, w, _ = img.shape
    with open(path, "wb") as f:
        f.write(f"PF\n{w} {h}\n-1.0\n".encode())
        f.write(img.tobytes())


def run(cmd, log=None, **kw):
    t0 = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True, **kw)
    if log:
        with open(log, "w") as f:
            f.write(" ".join(shlex.quote(c) for c in cmd) + "\n" + p.stdout + p.stderr)
    if p.returncode != 0:
        raise SystemExit(f"failed ({p.returncode}): {' '.join(cmd)}\n{p.stderr[-3000:]}")
    return p, time.perf_counter() - t0


def scale_camera(text, scale):
    """The scene text with the first [camera]'s width and height scaled."""
    if scale == 1.0:
        return text
    for key in ("width", "height"):
        text = re.sub(r"^(%s = )(\d+)$" % key, lambda m: m.group(1) + str(max(8, round(
            int(m.group(2)) * scale))), text, count=1, flags=re.M)
    return text


def set_camera(text, cam):
    """The scene text with its look-at camera's eye, target and fov replaced."""
    for key, val in (("eye", cam["eye"]), ("target", cam["target"]), ("fov_y_deg", cam["fov"])):
        v = generate.fmt(val) if key != "fov_y_deg" else str(val)
        text, n = re.subn(r"^%s = .*$" % key, f"{key} = {v}", text, count=1, flags=re.M)
        assert n == 1, key
    return text


def bundled_truth(scene_path):
    """truth.json's form for a bundled scene: each group's material from its first object."""
    sc = tomllib.load(open(scene_path, "rb"))
    groups = {}
    for o in sc.get("object", []):
        m = o.get("material")
        if "emission" in o or m is None or o["group"] in groups:
            continue
        t = {"model": m["type"], "rho_d": None, "rho_s": None, "alpha": None, "texture": None,
             "exact_in_matfit": True}
        for k in ("rho_d", "rho_s"):
            if k in m:
                t[k] = generate.rgb(m[k])
        if m["type"] == "mirror":
            t["rho_d"] = generate.rgb(0.0)
        if m["type"] == "diffuse":
            t["rho_s"] = None
        for k in ("alpha", "alpha_x", "alpha_y", "theta_deg"):
            if k in m:
                t[k] = m[k]
        if m["type"] == "textured":
            t["texture"] = m["texture"]
        groups[o["group"]] = t
    return {"groups": groups}


def prepare(name, work, scale, matfit):
    """Writes work/scene.toml, scene_novel.toml, truth.json and the two Mitsuba XMLs."""
    os.makedirs(work, exist_ok=True)
    if name in ("interior", "measured"):
        gen = os.path.join(work, "gen")
        run([sys.executable, os.path.join(ROOT, "scenes", "interior", "generate.py"), name,
             "-o", gen, "--matfit", matfit])
        for f in ("scene.toml", "scene_novel.toml"):
            text = scale_camera(open(os.path.join(gen, f)).read(), scale)
            open(os.path.join(gen, f), "w").write(text)
        for f, n in (("scene.toml", "scene.xml"), ("scene_novel.toml", "novel.xml")):
            generate.assemble_mitsuba(gen, matfit, f, n)
        truth = json.load(open(os.path.join(gen, "truth.json")))
        return gen, truth
    src = os.path.join(ROOT, "scenes", name)
    gen = os.path.join(work, "gen")
    shutil.rmtree(gen, ignore_errors=True)
    shutil.copytree(src, gen)
    text = scale_camera(open(os.path.join(gen, "scene.toml")).read(), scale)
    open(os.path.join(gen, "scene.toml"), "w").write(text)
    open(os.path.join(gen, "scene_novel.toml"), "w").write(set_camera(text, NOVEL[name]))
    truth = bundled_truth(os.path.join(gen, "scene.toml"))
    truth["novel_camera"] = NOVEL[name]
    for f, n in (("scene.toml", "scene.xml"), ("scene_novel.toml", "novel.xml")):
        out = os.path.join(gen, "mitsuba", os.path.splitext(n)[0])
        run([matfit, "export", "mitsuba", os.path.join(gen, f), "-o", out, "--force"])
        xml = open(os.path.join(out, "scene.xml")).read()
        xml = xml.replace('value="meshes/', f'value="{os.path.splitext(n)[0]}/meshes/')
        xml = xml.replace('value="textures/', f'value="{os.path.splitext(n)[0]}/textures/')
        xml = xml.replace('value="environment.exr"',
                          f'value="{os.path.splitext(n)[0]}/environment.exr"')
        open(os.path.join(gen, "mitsuba", n), "w").write(xml)
    return gen, truth


def mitsuba(mi, xml, spp, seed):
    mi.file_resolver().prepend(os.path.dirname(xml))
    scene = mi.load_file(xml)
    return np.array(mi.render(scene, spp=spp, seed=seed), dtype=np.float64)[..., :3]


def l1(a, b):
    return 100.0 * float(np.abs(a - b).sum() / max(np.abs(b).sum(), 1e-30))


# ---- (b) textures: a group's diffuse reflectance per photo pixel


def group_names(matfit, scene):
    """Group names in index order, from `matfit info`."""
    return [g for g, _ in group_info(matfit, scene)]


def group_info(matfit, scene):
    """(group, is an emitter) in index order: `matfit info` gives an emitter group no
    material after its objects."""
    out = subprocess.run([matfit, "info", scene], check=True, capture_output=True,
                         text=True).stdout
    return [(l.split()[1].rstrip(":"), ";" not in l) for l in out.splitlines()
            if l.startswith("group ")]


def albedo_scene(text):
    """Scene text whose materials are their diffuse part alone (a textured material's varnish
    removed, a uniform material made Lambert of its ρd, one without ρd black), with a white
    stray light: a pixel of a lone surface then shows its ρd."""
    def diffuse_part(m):
        line = m.group(0)
        if 'type = "textured"' in line:
            for k in ("rho_s", "alpha_x", "alpha_y", "alpha", "theta_deg", "distribution"):
                line = re.sub(r",\s*%s = (\[[^\]]*\]|\"[^\"]*\"|[-0-9.e]+)" % k, "", line)
            return line
        rho = re.search(r"rho_d = (\[[^\]]*\]|[-0-9.e]+)", line)
        return 'material = { type = "diffuse", rho_d = %s }' % (rho.group(1) if rho else "0.0")
    text = re.sub(r"^material = \{.*\}$", diffuse_part, text, flags=re.M)
    text = re.sub(r"^\[stray_light\]\n(radiance = .*\n)?", "", text, flags=re.M)
    return text + "\n[stray_light]\nradiance = [1.0, 1.0, 1.0]\n"


def albedo_image(matfit, scene_path, group, names, objects_of, work, tag, spp=16):
    """The group's ρd as the photo's camera sees it: only its objects kept, no lights, a white
    stray light."""
    text = albedo_scene(open(scene_path).read())
    path = os.path.join(os.path.dirname(scene_path), f".albedo_{tag}.toml")
    open(path, "w").write(text)
    cmd = [matfit, "render", path, "-o", os.path.join(work, f"albedo_{tag}.pfm"), "--spp",
           str(spp), "--seed", "1"]
    # matfit refuses a scene with no emitter: the lights are kept, dimmed to nothing and moved
    # 1 km up, where they hide a negligible part of the white sky.
    for g, emitter in group_info(matfit, scene_path):
        if emitter:
            cmd += ["--scale-light", f"{g}=1e-9", "--move", f"{g}=0,1000,0"]
        elif g != group:
            cmd += ["--remove", g]
    run(cmd)
    os.remove(path)
    return read_pfm(os.path.join(work, f"albedo_{tag}.pfm"))


def eroded(mask, r=1):
    h, w = mask.shape
    pad = np.pad(mask, r, constant_values=False)
    out = mask.copy()
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            out &= pad[r + dy:r + dy + h, r + dx:r + dx + w]
    return out


def psnr(a, b):
    mse = float(((a - b) ** 2).mean())
    return 99.0 if mse <= 0 else 10 * math.log10(1.0 / mse)


# ---- (d) coverage


def coverage(truth_groups, res_groups, same_level=False):
    """(covered, scored, not determined, absent, per-group notes). With `same_level`, only
    the groups recovered at their truth's own level (truth.json's `level`), whose parameters
    mean what the truth's do."""
    cov = scored = undet = absent = 0
    rows = {}
    for g, t in truth_groups.items():
        r = res_groups.get(g)
        if r is None:
            continue
        if same_level and (t.get("level") is None or t.get("level") != r.get("level_number")):
            continue
        params, sigma = r.get("params") or {}, r.get("sigma") or {}
        pairs = []
        for key in ("rho_d", "rho_s"):
            if t.get(key) is not None:
                pairs.append((key, key, t[key]))
        for key in ("alpha", "alpha_x"):
            if t.get(key) is not None:
                pairs.append((key, "alpha_x", [t[key]]))
        if t.get("alpha_y") is not None:
            pairs.append(("alpha_y", "alpha_y", [t["alpha_y"]]))
        elif t.get("alpha") is not None and "alpha_y" in params:
            pairs.append(("alpha", "alpha_y", [t["alpha"]]))
        c = s = u = a = 0
        for _, rkey, tv in pairs:
            est, sig = params.get(rkey), sigma.get(rkey)
            tv = list(tv)
            if est is None:
                a += len(tv)
                continue
            est = est if isinstance(est, list) else [est] * len(tv)
            sig = sig if isinstance(sig, list) else [sig] * len(tv)
            for e, sg, tr in zip(est, sig, tv):
                if sg is None:
                    u += 1
                elif abs(e - tr) <= 2 * sg:
                    c += 1
                    s += 1
                else:
                    s += 1
        cov, scored, undet, absent = cov + c, scored + s, undet + u, absent + a
        rows[g] = (c, s, u, a)
    return cov, scored, undet, absent, rows


def albedo_coverage(truth_groups, res_groups):
    """±2σ coverage of the directional albedo at 0° and 60° per channel (results.json's
    `albedo` against truth.json's `albedo_0deg` / `albedo_60deg`, which Mitsuba computes from
    the true BSDF), over every uniform fitted group whatever its level: (covered, scored, not
    determined, per-group (covered, scored, not determined))."""
    cov = scored = undet = 0
    rows = {}
    for g, t in truth_groups.items():
        r = res_groups.get(g)
        if (r is None or t.get("texture") or "textured" in str(t.get("model", ""))
                or r.get("status") in ("light", "fixed") or not r.get("albedo")
                or t.get("albedo_0deg") is None or t.get("albedo_60deg") is None):
            continue
        ra = r["albedo"]
        c = s = u = 0
        for tv, ev, sv in zip(t["albedo_0deg"] + t["albedo_60deg"],
                              ra["normal"] + ra["at_60deg"],
                              ra["sigma_normal"] + ra["sigma_60deg"]):
            if sv is None:
                u += 1
            else:
                s += 1
                c += abs(ev - tv) <= 2 * sv
        cov, scored, undet = cov + c, scored + s, undet + u
        rows[g] = (c, s, u)
    return cov, scored, undet, rows


# ---- one scene


def run_scene(name, a, matfit, mi):
    work = os.path.join(a.out, name)
    t0 = time.perf_counter()
    gen, truth = prepare(name, work, a.scale, matfit)
    scene = os.path.join(gen, "scene.toml")
    names = group_names(matfit, scene)
    cam = truth["novel_camera"]
    photo = os.path.join(work, "photo.pfm")
    tp = time.perf_counter()
    write_pfm(photo, mitsuba(mi, os.path.join(gen, "mitsuba", "scene.xml"), a.photo_spp, 1))
    photo_s = time.perf_counter() - tp
    tp = time.perf_counter()
    nov1 = mitsuba(mi, os.path.join(gen, "mitsuba", "novel.xml"), a.novel_spp, 1)
    nov2 = mitsuba(mi, os.path.join(gen, "mitsuba", "novel.xml"), a.novel_spp, 2)
    novel_s = time.perf_counter() - tp
    write_pfm(os.path.join(work, "novel_mitsuba.pfm"), nov1)
    floor = l1(nov2, nov1)
    print(f"{name}: photo {photo_s:.0f} s, novel x2 {novel_s:.0f} s (Mitsuba); "
          f"noise floor {floor:.2f}%", flush=True)

    # Group index buffer of the photo, for the texture masks.
    run([matfit, "render", scene, "--aov", "group", "-o", os.path.join(work, "group.pfm")])
    ids = read_pfm(os.path.join(work, "group.pfm"))[..., 0].round().astype(int)
    textured = [g for g, t in truth["groups"].items() if t.get("texture")]
    true_albedo = {g: albedo_image(matfit, scene, g, names, None, work, f"truth_{g}")
                   for g in textured if g in names}

    with open(os.path.join(work, "floor.json"), "w") as f:
        json.dump({"floor": floor, "photo_s": photo_s, "novel_s": novel_s}, f)
    seeds = []
    r = {"name": name, "truth": truth, "floor": floor, "seeds": seeds, "photo_s": photo_s,
         "novel_s": novel_s, "total_s": time.perf_counter() - t0}  # --seeds 0: photos only
    for s in range(1, a.seeds + 1):
        out = os.path.join(work, f"seed{s}")
        cmd = [matfit, "recover", scene, photo, "-o", out, "--seed", str(s), "--force"]
        cmd += shlex.split(a.recover_args)
        _, wall = run(cmd, log=os.path.join(work, f"recover_seed{s}.log"))
        seeds.append(score_seed(matfit, work, s, wall, truth, names, ids, true_albedo, nov1, a))
        r = {"name": name, "truth": truth, "floor": floor, "seeds": seeds, "photo_s": photo_s,
             "novel_s": novel_s, "total_s": time.perf_counter() - t0}
        with open(os.path.join(work, "summary.json"), "w") as f:  # after every seed
            json.dump(r, f, indent=1, default=str)
        c = seeds[-1]["coverage"]
        print(f"  seed {s}: recover {wall:.0f} s, novel L1 {seeds[-1]['novel']:.2f}% (floor "
              f"{floor:.2f}%), coverage {c[0]}/{c[1]} (+{c[2]} not determined, {c[3]} absent)",
              flush=True)
    return r


def novel_by_group(matfit, work, img, ref, names):
    """Each group's points of the novel view's L1: Σ|a − b| over the pixels the novel camera
    sees it in, over Σ b of the whole image (so they add up to the novel L1). The novel
    camera's group buffer is rendered once per scene folder. {} without gen/scene_novel.toml."""
    scene = os.path.join(work, "gen", "scene_novel.toml")
    if not os.path.exists(scene):
        return {}
    buf = os.path.join(work, "novel_group.pfm")
    if not os.path.exists(buf):
        run([matfit, "render", scene, "--aov", "group", "-o", buf, "--spp", "1"])
    ids = read_pfm(buf)[..., 0].round().astype(int)
    err = np.abs(img[..., :3] - ref[..., :3]).sum(-1)
    total = max(float(np.abs(ref[..., :3]).sum()), 1e-30)
    out = {g: 100.0 * float(err[ids == i].sum()) / total for i, g in enumerate(names)}
    out["(background)"] = 100.0 * float(err[(ids < 0) | (ids >= len(names))].sum()) / total
    return out


def score_seed(matfit, work, s, wall, truth, names, ids, true_albedo, nov1, a):
    """Scores the recovery in work/seedS: novel view, textures, levels, coverage."""
    out = os.path.join(work, f"seed{s}")
    cam = truth["novel_camera"]
    res = json.load(open(os.path.join(out, "results.json")))
    groups = {g["name"]: g for g in res["groups"]}
    rec = os.path.join(out, "recovered.toml")
    nov = os.path.join(work, f"novel_seed{s}.pfm")
    if not (a.rescore and os.path.exists(nov)):  # a rescore keeps the renders it finds
        run([matfit, "render", rec, "-o", nov, "--spp", str(a.novel_spp), "--seed", "1",
             "--look-from=" + ",".join(map(str, cam["eye"])),
             "--look-at=" + ",".join(map(str, cam["target"])), "--fov", str(cam["fov"])])
    novel_l1 = l1(read_pfm(nov).astype(np.float64), nov1)
    by_group = novel_by_group(matfit, work, read_pfm(nov).astype(np.float64), nov1, names)
    tex = {}
    for g in true_albedo:
        mask = eroded(ids == names.index(g))
        if mask.sum() < 20:
            tex[g] = None
            continue
        done = os.path.join(out, f"albedo_rec_{g}.pfm")
        ra = read_pfm(done) if a.rescore and os.path.exists(done) else albedo_image(
            matfit, rec, g, names, None, out, f"rec_{g}")
        t_, r_ = true_albedo[g][mask].astype(np.float64), ra[mask].astype(np.float64)
        gain = (t_ * r_).sum(0) / np.maximum((r_ * r_).sum(0), 1e-12)
        tex[g] = (psnr(r_, t_), psnr(r_ * gain, t_), int(mask.sum()),
                  groups.get(g, {}).get("level"), psnr(t_.mean(0), t_))
    return {"seed": s, "wall": wall, "timing": res.get("timing"), "novel": novel_l1,
            "novel_by_group": by_group,
            "levels": {g: groups[g].get("level") for g in groups},
            "status": {g: groups[g].get("status") for g in groups},
            "tex": tex, "coverage": coverage(truth["groups"], groups),
            "coverage_same": coverage(truth["groups"], groups, same_level=True),
            "coverage_albedo": albedo_coverage(truth["groups"], groups)}


def rescore(name, a, matfit):
    """Scores the recoveries an earlier (perhaps interrupted) run left in OUT/SCENE/seed*/,
    without rendering the photo or recovering again, reusing the novel-view and albedo renders
    it finds; a seed's time is then results.json's total_s (the recovery's own, without the
    process start)."""
    work = os.path.join(a.out, name)
    gen = os.path.join(work, "gen")
    scene = os.path.join(gen, "scene.toml")
    truth = json.load(open(os.path.join(gen, "truth.json"))) if os.path.exists(
        os.path.join(gen, "truth.json")) else bundled_truth(scene)
    truth.setdefault("novel_camera", NOVEL.get(name))
    names = group_names(matfit, scene)
    ids = read_pfm(os.path.join(work, "group.pfm"))[..., 0].round().astype(int)
    true_albedo = {}
    for g, t in truth["groups"].items():
        path = os.path.join(work, f"albedo_truth_{g}.pfm")
        if t.get("texture") and os.path.exists(path):
            true_albedo[g] = read_pfm(path)
    nov1 = read_pfm(os.path.join(work, "novel_mitsuba.pfm")).astype(np.float64)
    meta = {"floor": float("nan"), "photo_s": 0.0, "novel_s": 0.0}
    if os.path.exists(os.path.join(work, "floor.json")):
        meta = json.load(open(os.path.join(work, "floor.json")))
    seeds = []
    found = [int(m.group(1)) for d in os.listdir(work) if (m := re.fullmatch(r"seed(\d+)", d))]
    for s in sorted(found):
        if not os.path.exists(os.path.join(work, f"seed{s}", "results.json")):
            continue
        wall = json.load(open(os.path.join(work, f"seed{s}", "results.json")))["timing"]["total_s"]
        seeds.append(score_seed(matfit, work, s, wall, truth, names, ids, true_albedo, nov1, a))
    r = {"name": name, "truth": truth, "seeds": seeds, "total_s": 0.0, **meta}
    with open(os.path.join(work, "summary.json"), "w") as f:
        json.dump(r, f, indent=1, default=str)
    return r


def report(r, a):
    L = []
    seeds = r["seeds"]
    n = len(seeds)
    tri = r["truth"].get("triangles")
    L.append(f"### {r['name']}" + (f" ({tri} triangles)" if tri else ""))
    L.append("")
    L.append(f"Mitsuba photo {r['photo_s']:.0f} s, novel view ×2 {r['novel_s']:.0f} s; "
             f"scene total {r['total_s'] / 60:.1f} min.")
    L.append("")
    L.append("| seed | recover (s) | novel L1 | noise floor | ±2σ coverage | not determined | "
             "absent | ±2σ, truth's level | ±2σ albedo |")
    L.append("|---|---|---|---|---|---|---|---|---|")

    def share(c):
        return (f"{100 * c[0] / c[1]:.0f}% ({c[0]}/{c[1]})" if c[1] else "–") + (
            f" +{c[2]}u" if len(c) > 2 and c[2] else "")
    for s in seeds:
        c = s["coverage"]
        same = share(s["coverage_same"][:3]) if s.get("coverage_same") else "–"
        alb = share(s["coverage_albedo"][:3]) if s.get("coverage_albedo") else "–"
        L.append(f"| {s['seed']} | {s['wall']:.0f} | {s['novel']:.2f}% | {r['floor']:.2f}% | "
                 f"{share(c[:2])} | {c[2]} | {c[3]} | {same} | {alb} |")
    L.append("")
    # (c) levels
    groups = sorted({g for s in seeds for g in s["levels"]},
                    key=lambda g: list(r["truth"]["groups"]).index(g)
                    if g in r["truth"]["groups"] else 999)
    L.append("| group | truth | " + " | ".join(f"seed {s['seed']}" for s in seeds)
             + " | agree | 2σ hits | albedo 2σ hits |")
    L.append("|---|---|" + "---|" * n + "---|---|---|")
    for g in groups:
        if all(s["status"].get(g) == "light" for s in seeds):
            continue
        t = r["truth"]["groups"].get(g, {})
        lv = [s["levels"].get(g) or "–" for s in seeds]
        top = max(set(lv), key=lv.count)
        agree = f"{lv.count(top)}/{n}" + (" ✓" if lv.count(top) >= math.ceil(0.8 * n) else " ✗")
        hits = []
        for s in seeds:
            c = s["coverage"][4].get(g)
            hits.append("–" if not c or not (c[1] + c[2] + c[3]) else
                        f"{c[0]}/{c[1]}" + (f"+{c[2]}u" if c[2] else "")
                        + (f"+{c[3]}a" if c[3] else ""))
        ahits = []
        for s in seeds:
            c = (s.get("coverage_albedo") or [None] * 4)[3]
            c = c.get(g) if c else None
            ahits.append("–" if not c else f"{c[0]}/{c[1]}" + (f"+{c[2]}u" if c[2] else ""))
        model = t.get("model", "?")
        L.append(f"| {g} | {model} | " + " | ".join(
            f"{l} ({s['status'].get(g, '')})" for l, s in zip(lv, seeds))
            + f" | {agree} | {' '.join(hits)} | {' '.join(ahits)} |")
    L.append("")
    tex_groups = sorted({g for s in seeds for g in s["tex"]})
    if tex_groups:
        L.append("| textured group | pixels | flat | " + " | ".join(
            f"seed {s['seed']} PSNR / PSNR* (level)" for s in seeds) + " |")
        L.append("|---|---|---|" + "---|" * n)
        for g in tex_groups:
            px = next((s["tex"][g][2] for s in seeds if s["tex"].get(g)), 0)
            flat = next((s["tex"][g][4] for s in seeds
                         if s["tex"].get(g) and len(s["tex"][g]) > 4), None)
            cells = []
            for s in seeds:
                v = s["tex"].get(g)
                cells.append("–" if v is None else f"{v[0]:.1f} / {v[1]:.1f} dB ({v[3]})")
            L.append(f"| {g} | {px} | " + ("–" if flat is None else f"{flat:.1f} dB") + " | "
                     + " | ".join(cells) + " |")
        L.append("")
    by_group = [s.get("novel_by_group") or {} for s in seeds]
    worst = sorted({g for b in by_group for g in b}, key=lambda g: -max(b.get(g, 0) for b in by_group))
    worst = [g for g in worst if max(b.get(g, 0) for b in by_group) >= 0.1]
    if worst:
        L.append("| novel view's L1 by group (points) | " + " | ".join(
            f"seed {s['seed']}" for s in seeds) + " |")
        L.append("|---|" + "---|" * n)
        for g in worst:
            L.append(f"| {g} | " + " | ".join(
                f"{b[g]:.2f}" if g in b else "–" for b in by_group) + " |")
        L.append("")
    return "\n".join(L)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenes", nargs="*", default=["interior", "measured", "figure6", "poster"])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--scale", type=float, default=1.0, help="photo resolution scale")
    ap.add_argument("--photo-spp", type=int, default=256)
    ap.add_argument("--novel-spp", type=int, default=128)
    ap.add_argument("--recover-args", default="", help="extra options for matfit recover")
    ap.add_argument("--matfit", help="matfit binary (default: target/release)")
    ap.add_argument("--threads", type=int, default=0, help="Mitsuba's threads (0: all)")
    ap.add_argument("--out", default=os.path.join(HERE, "out", "decisions"))
    ap.add_argument("--md", help="markdown report (default OUT/DECISIONS.md)")
    ap.add_argument("--rescore", action="store_true",
                    help="score the recoveries an earlier run left in OUT/SCENE/seed*/ again "
                         "(no photo, no recovery)")
    ap.add_argument("--from-summary", action="store_true",
                    help="only print the report of an earlier run (OUT/SCENE/summary.json)")
    a = ap.parse_args()
    if a.from_summary:
        for name in a.scenes:
            path = os.path.join(a.out, name, "summary.json")
            if os.path.exists(path):
                print(report(json.load(open(path)), a))
        return
    matfit = find_matfit(a.matfit)
    mi = None
    if not a.rescore:  # a rescore renders with matfit only
        import drjit as dr
        import mitsuba as mi
        mi.set_variant("llvm_ad_rgb")
        mi.set_log_level(mi.LogLevel.Error)
        if a.threads:
            dr.set_thread_count(a.threads)
    load = open("/proc/loadavg").read().split()[:3]
    git = subprocess.run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"],
                         capture_output=True, text=True).stdout.strip()
    head = [f"## decisions run, {datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC",
            "", f"`python bench/decisions.py {' '.join(sys.argv[1:])}` at git {git}, "
            f"{platform.node()} ({os.cpu_count()} cores), load before {' '.join(load)}.", ""]
    parts = []
    md = a.md or os.path.join(a.out, "DECISIONS.md")
    os.makedirs(os.path.dirname(os.path.abspath(md)), exist_ok=True)
    for name in a.scenes:
        r = rescore(name, a, matfit) if a.rescore else run_scene(name, a, matfit, mi)
        parts.append(report(r, a))
        print(parts[-1], flush=True)
        load = open("/proc/loadavg").read().split()[:3]
        with open(md, "w") as f:  # after every scene, so that a long run's first ones are kept
            f.write("\n".join(head + parts + [f"Load after: {' '.join(load)}.", ""]))
    print(f"wrote {md}")


if __name__ == "__main__":
    main()
