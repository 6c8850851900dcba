#!/usr/bin/env python3
"""Import check over public scenes (issue 80): what Mitsuba 3 loads, what matfit imports, and,
for each scene both load, matfit's render against Mitsuba's per group.

    bash bench/setup_mitsuba.sh && source bench/mitsuba_env.sh
    python bench/import_public.py [--md bench/IMPORT_PUBLIC.md] [--only NAME,...]

Scenes come from public GitHub repositories (the list SCENES below): Mitsuba's own test and
tutorial scenes (mitsuba-renderer/mitsuba-data) and Benedikt Bitterli's rendering resources as
he published them for Mitsuba 0.5 (mirrored in jgarciapueyo/mitsuba2-transient-scenes). They
are fetched into a cache outside the repository (--cache, default ~/.cache/matfit-import-public),
never committed: from a local bare mirror when --mirrors holds one (`OWNER+NAME/repo`), else by
`git clone --filter=blob:none`. A file the mirror lacks (large files) gets a stand-in, and the
table says which: a missing mesh's <shape> is removed from the XML both renderers read, a
missing image becomes a grey one of the same name. One scene is a stand-in written here:
`oldformat`, a Mitsuba 0.5 file in the published scenes' idiom (toWorld, lookAt, sampleCount,
maxDepth, diffuseReflectance, intIOR, uscale, a serialized mesh, a disk, a checkerboard, an
include and a <path>).

For each scene:
- Mitsuba 3 loads the XML as published (`mi.load_file`); if it refuses a property Mitsuba 3
  itself no longer knows (Mitsuba 0.5's `high_quality_edges`, `ldrfilm`), the script removes that
  and says so ("loads after: ...");
- `matfit import mitsuba` imports the same XML (warnings counted, refusals quoted);
- when both load, both render at --width pixels wide (the film's aspect kept), --spp samples, two
  seeds each, Mitsuba with a box pixel filter, matfit's (--mitsuba-filter xml keeps the XML's;
  the import warns about it); groups are compared as in import_check.py (matfit's group buffer,
  masks eroded by 2 px, |rel| <= --tol + 3 sigma).

The Markdown file's text from the line INVESTIGATIONS on is kept when --md rewrites it.
"""
import argparse
import datetime
import os
import platform
import re
import shutil
import struct
import subprocess
import sys
import time
import zlib

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import crosscheck as cc  # noqa: E402

ROOT = cc.ROOT
DATA = "mitsuba-renderer/mitsuba-data"
BITTERLI = "jgarciapueyo/mitsuba2-transient-scenes"

# (name, repository, XML path in it, folders to fetch)
SCENES = [
    ("cbox", DATA, "scenes/cbox/cbox.xml", ["scenes/cbox"]),
    ("cbox-rgb", DATA, "scenes/cbox/cbox-rgb.xml", ["scenes/cbox"]),
    ("matpreview", DATA, "scenes/matpreview/matpreview.xml", ["scenes/matpreview"]),
    ("docs-shape_disk", DATA, "docs/scenes/shape_disk.xml", ["docs/scenes", "common"]),
    ("docs-texture_checkerboard", DATA, "docs/scenes/texture_checkerboard.xml",
     ["docs/scenes", "common"]),
    ("docs-bsdf_roughplastic_diffuse", DATA, "docs/scenes/bsdf_roughplastic_diffuse.xml",
     ["docs/scenes", "common"]),
    ("docs-bsdf_bumpmap_with", DATA, "docs/scenes/bsdf_bumpmap_with.xml", ["docs/scenes", "common"]),
    ("bitterli-living-room", BITTERLI, "living-room/scene.xml", ["living-room"]),
    ("bitterli-staircase", BITTERLI, "staircase/scene.xml", ["staircase"]),
    ("bitterli-staircase2", BITTERLI, "staircase2/scene.xml", ["staircase2"]),
    ("bitterli-dining-room", BITTERLI, "dining-room/scene.xml", ["dining-room"]),
    ("bitterli-kitchen", BITTERLI, "kitchen/scene.xml", ["kitchen"]),
    ("bitterli-bathroom", BITTERLI, "bathroom/scene.xml", ["bathroom"]),
    ("bitterli-bathroom2", BITTERLI, "bathroom2/scene.xml", ["bathroom2"]),
    ("oldformat", None, "oldformat/scene.xml", []),
]

# Groups outside the tolerance whose cause is established (by the import's own warning, or in
# the Investigations section below the table): the note the table gives them when outside.
EXPLAINED = {
    ("docs-bsdf_bumpmap_with", "object_bsdf"): "object_bsdf: its bump map dropped",
    ("bitterli-staircase2", "Glass"): "Glass: a `dielectric` imported as opaque diffuse 0.5",
    ("bitterli-staircase2", "Wall"):
        "Wall: lit through the Glass panel beside the stairs, which matfit makes opaque "
        "(Mitsuba with that Glass as the imported diffuse 0.5: 0.2%)",
}


def run(cmd, **kw):
    return subprocess.run(cmd, capture_output=True, text=True, **kw)


def git_dir(repo, mirrors, cache):
    """A git directory holding `repo`: a local mirror, or a blobless clone in the cache."""
    if mirrors:
        d = os.path.join(mirrors, repo.replace("/", "+"), "repo")
        if os.path.isdir(d):
            return d
    d = os.path.join(cache, "git", repo.replace("/", "+"))
    if not os.path.isdir(d):
        r = run(["git", "clone", "--bare", "--filter=blob:none", "--depth", "1",
                 f"https://github.com/{repo}", d])
        if r.returncode != 0:
            return None
    return d


def extract(gd, folders, dest):
    """Writes `folders` of HEAD into dest; returns the paths whose contents are absent."""
    missing = []
    for folder in folders:
        out = run(["git", "--git-dir", gd, "ls-tree", "-r", "HEAD", folder]).stdout
        for line in out.splitlines():
            meta, path = line.split("\t", 1)
            sha = meta.split()[2]
            p = os.path.join(dest, path)
            if os.path.exists(p):
                continue
            r = subprocess.run(["git", "--git-dir", gd, "cat-file", "blob", sha],
                               capture_output=True)
            if r.returncode != 0 or r.stdout.startswith(b"version https://git-lfs"):
                missing.append(path)
                continue
            os.makedirs(os.path.dirname(p), exist_ok=True)
            with open(p, "wb") as f:
                f.write(r.stdout)
    return missing


def stand_ins(xml_path, missing_abs, mi):
    """Stand-ins for absent files: a shape whose mesh is absent is removed from the XML, an
    absent image becomes a grey one. Returns the notes for the table."""
    notes, text = [], open(xml_path).read()
    meshes = [p for p in missing_abs if p.lower().endswith((".obj", ".ply", ".serialized"))]
    removed = 0
    for p in meshes:
        rel = os.path.relpath(p, os.path.dirname(xml_path))
        pat = re.compile(r"<shape\b(?:(?!</shape>).)*?" + re.escape(rel) +
                         r".*?</shape>", re.S)
        text, n = pat.subn(lambda m: "<!-- stand-in: shape removed -->" +
                           "\n" * m.group(0).count("\n"), text)
        removed += n
    if removed:
        notes.append(f"{removed} shape(s) whose mesh is absent from the mirror removed")
    images = [p for p in missing_abs if p.lower().endswith((".png", ".jpg", ".exr", ".hdr",
                                                             ".tga", ".bmp"))]
    for p in images:
        os.makedirs(os.path.dirname(p), exist_ok=True)
        if p.lower().endswith(".hdr"):
            # Radiance's format, flat scanlines of RGBE 0.5 (both renderers read it).
            with open(p, "wb") as f:
                f.write(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 32 +X 64\n")
                f.write(bytes([128, 128, 128, 128]) * (64 * 32))
            continue
        if p.lower().endswith(".exr"):
            grey = np.full((4, 8, 3), 0.5, dtype=np.float32)
        else:
            grey = np.full((4, 8, 3), 188, dtype=np.uint8)  # 0.5 linear, sRGB-encoded
        mi.Bitmap(grey).write(p)
    if images:
        notes.append(f"{len(images)} absent image(s) replaced by grey: " +
                     ", ".join(os.path.basename(p) for p in images))
    with open(xml_path, "w") as f:
        f.write(text)
    return notes


def serialized_v4(shapes):
    """A Mitsuba 0.5 serialized file (version 4) of [(positions, uvs, triangles)]."""
    out, offsets = b"", []
    for pos, uv, tri in shapes:
        offsets.append(len(out))
        raw = struct.pack("<I", 0x1000 | (0x2 if uv else 0)) + b"mesh\0"
        raw += struct.pack("<QQ", len(pos), len(tri))
        raw += b"".join(struct.pack("<3f", *p) for p in pos)
        if uv:
            raw += b"".join(struct.pack("<2f", *t) for t in uv)
        raw += b"".join(struct.pack("<3I", *t) for t in tri)
        out += struct.pack("<HH", 0x041C, 4) + zlib.compress(raw)
    out += b"".join(struct.pack("<Q", o) for o in offsets) + struct.pack("<I", len(shapes))
    return out


def write_oldformat(dest, mi):
    """The stand-in Mitsuba 0.5 scene: a room of rectangles, a serialized box-ish mesh, a disk
    light, a checkerboard floor, an include and a <path> folder with a texture."""
    d = os.path.join(dest, "oldformat")
    os.makedirs(os.path.join(d, "assets"), exist_ok=True)
    quad = ([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)],
            [(0, 1), (1, 1), (1, 0), (0, 0)], [(0, 1, 2), (0, 2, 3)])
    tent = ([(-1, 0, -1), (1, 0, -1), (0, 1.5, 0), (0, 0, 1)], None,
            [(0, 1, 2), (1, 3, 2), (3, 0, 2)])
    with open(os.path.join(d, "assets", "parts.serialized"), "wb") as f:
        f.write(serialized_v4([quad, tent]))
    ramp = np.zeros((16, 32, 3), dtype=np.float32)
    ramp[..., 0] = np.linspace(0.2, 0.8, 32)[None, :]
    ramp[..., 1] = np.linspace(0.7, 0.3, 16)[:, None]
    ramp[..., 2] = 0.35
    mi.Bitmap(ramp).write(os.path.join(d, "assets", "ramp.exr"))
    with open(os.path.join(d, "walls.xml"), "w") as f:
        f.write("""<scene version="0.5.0">
	<shape type="rectangle">
		<transform name="toWorld"><scale x="3" y="2"/><translate z="-3"/></transform>
		<bsdf type="diffuse"><rgb name="diffuseReflectance" value="0.6, 0.55, 0.5"/></bsdf>
	</shape>
	<shape type="rectangle">
		<transform name="toWorld"><scale x="3" y="3"/><rotate y="1" angle="90"/>
			<translate x="-3"/></transform>
		<bsdf type="diffuse"><spectrum name="diffuseReflectance" value="0.35"/></bsdf>
	</shape>
</scene>
""")
    with open(os.path.join(d, "scene.xml"), "w") as f:
        f.write("""<?xml version="1.0" encoding="utf-8"?>
<scene version="0.5.0">
	<path value="assets"/>
	<integrator type="path">
		<integer name="maxDepth" value="6"/>
		<integer name="rrDepth" value="5"/>
	</integrator>
	<sensor type="perspective">
		<float name="fov" value="55"/>
		<string name="fovAxis" value="x"/>
		<transform name="toWorld">
			<lookAt origin="0.3, 0.4, 4.2" target="0, -0.3, 0" up="0, 1, 0"/>
		</transform>
		<sampler type="independent"><integer name="sampleCount" value="64"/></sampler>
		<film type="hdrfilm">
			<integer name="width" value="320"/><integer name="height" value="240"/>
			<rfilter type="box"/>
		</film>
	</sensor>
	<include filename="walls.xml"/>
	<texture type="checkerboard" id="checks">
		<rgb name="color0" value="0.7"/>
		<rgb name="color1" value="0.15"/>
		<transform name="toUV"><scale x="4" y="4"/></transform>
	</texture>
	<shape type="rectangle" id="floor">
		<transform name="toWorld"><scale x="3" y="3"/><rotate x="1" angle="-90"/>
			<translate y="-1"/></transform>
		<bsdf type="diffuse"><ref name="reflectance" id="checks"/></bsdf>
	</shape>
	<shape type="serialized" id="poster">
		<string name="filename" value="parts.serialized"/>
		<integer name="shapeIndex" value="0"/>
		<transform name="toWorld"><scale x="0.8" y="0.6"/><translate x="1.2" y="0.3" z="-2.95"/></transform>
		<bsdf type="roughplastic">
			<float name="alpha" value="0.2"/>
			<string name="distribution" value="ggx"/>
			<float name="intIOR" value="1.5"/>
			<float name="extIOR" value="1.0"/>
			<texture type="bitmap" name="diffuseReflectance">
				<string name="filename" value="ramp.exr"/>
			</texture>
		</bsdf>
	</shape>
	<shape type="serialized" id="tent">
		<string name="filename" value="parts.serialized"/>
		<integer name="shapeIndex" value="1"/>
		<transform name="toWorld"><scale value="0.6"/><translate x="-0.8" y="-1" z="-1"/></transform>
		<bsdf type="twosided"><bsdf type="roughconductor">
			<string name="distribution" value="ggx"/>
			<float name="alphaU" value="0.3"/>
			<float name="alphaV" value="0.3"/>
			<string name="material" value="none"/>
			<rgb name="specularReflectance" value="0.8, 0.6, 0.4"/>
		</bsdf></bsdf>
	</shape>
	<shape type="disk" id="lamp">
		<transform name="toWorld"><scale value="0.5"/><rotate x="1" angle="90"/>
			<translate y="1.9" z="-1"/></transform>
		<emitter type="area"><rgb name="radiance" value="12, 11, 9"/></emitter>
	</shape>
</scene>
""")
    return os.path.join(d, "scene.xml")


# Properties and plugins of Mitsuba 0.5 that Mitsuba 3 refuses, and what replaces them.
MITSUBA3_FIXES = [
    (re.compile(r"<lookAt\b"), "<lookat",
     "<lookAt> as <lookat> (Mitsuba 3.9 no longer upgrades the tag)"),
    (re.compile(r'<boolean name="high_quality_edges"[^>]*/>'), "",
     "removed hdrfilm's `high_quality_edges` (a Mitsuba 0.5 property)"),
    (re.compile(r'<boolean name="highQualityEdges"[^>]*/>'), "",
     "removed hdrfilm's `highQualityEdges` (a Mitsuba 0.5 property)"),
    (re.compile(r'type="ldrfilm"'), 'type="hdrfilm"', "ldrfilm (Mitsuba 0.5) as hdrfilm"),
    (re.compile(r'<(float|string|boolean) name="(tonemapMethod|gamma|exposure|key|burn|'
                r'fileFormat)"[^>]*/>'), "", "removed ldrfilm's tone-mapping properties"),
    (re.compile(r'type="(sobol|halton|hammersley)"'), 'type="independent"',
     "a sobol/halton sampler (absent from Mitsuba 3) as independent"),
]


def mitsuba_load(mi, xml, fix):
    """(loaded, fixes applied, error). With fix, retries after each applicable fix."""
    applied = []
    while True:
        try:
            mi.load_file(xml)
            return True, applied, None
        except Exception as e:  # noqa: BLE001 (Mitsuba raises plain exceptions)
            err = str(e).strip().splitlines()
            err = " ".join(err[:3])[:300]
            if not fix:
                return False, applied, err
            text = open(xml).read()
            for pat, rep, note in MITSUBA3_FIXES:
                if note not in applied and pat.search(text):
                    text = pat.sub(rep, text)
                    applied.append(note)
                    break
            else:
                return False, applied, err
            with open(xml, "w") as f:
                f.write(text)


INVESTIGATIONS = "## Investigations (kept when the script rewrites this file)"


def small_film(xml, width, box=True):
    """The film's width set to `width` and its height to keep the aspect (the XML's own values
    or its <default>s resolved by hand), in the XML or a file it includes; returns
    (width, height) or None."""
    text = open(xml).read()
    if '<integer name="width"' not in text:
        for inc in re.findall(r'<include filename="([^"]+)"', text):
            p = os.path.join(os.path.dirname(xml), inc)
            if os.path.exists(p) and '<integer name="width"' in open(p).read():
                return small_film(p, width, box)
        return None
    defaults = dict(re.findall(r'<default name="(\w+)" value="([^"]+)"', text))

    def value(name):
        m = re.search(r'<integer name="%s" value="([^"]+)"' % name, text)
        if not m:
            return None, None
        v = m.group(1)
        return m, int(defaults.get(v[1:], 0) if v.startswith("$") else v)

    mw, w = value("width")
    mh, h = value("height")
    w, h = w or 768, h or 576
    nh = max(8, round(width * h / w))
    if mw:
        text = text.replace(mw.group(0), f'<integer name="width" value="{width}"')
    if mh:
        text = text.replace(mh.group(0), f'<integer name="height" value="{nh}"')
    if not mw or not mh:
        return None
    if box:
        text = box_filter(text)
    with open(xml, "w") as f:
        f.write(text)
    return width, nh


def box_filter(text):
    """The film's pixel filter made a box, matfit's: with Mitsuba's tent or gaussian, a sharp
    highlight spreads into the pixels beside it, which the masks' erosion (based on the groups
    seen at pixel centres) does not exclude. The import warns about the XML's own filter."""
    box = '<rfilter type="box"/>'
    if re.search(r"<rfilter\b", text):
        text = re.sub(r"<rfilter\b[^>]*/>", box, text)
        text = re.sub(r"<rfilter\b[^>]*[^/]>.*?</rfilter>", box, text, flags=re.S)
    else:
        text = text.replace("</film>", box + "</film>", 1)
    return text


def compare(exe, mi, dr, xml, work, spp, threads, tol):
    scene = os.path.join(work, "scene.toml")
    r = run([exe, "import", "mitsuba", xml, "-o", scene])
    if r.returncode != 0:
        return None
    run([exe, "render", scene, "--aov", "group", "-o", os.path.join(work, "ids.pfm")],
        check=True)
    ids = np.rint(cc.read_pfm(os.path.join(work, "ids.pfm"))[..., 0]).astype(int)
    names = cc.group_names(exe, scene)
    mf, t1 = cc.matfit_render(exe, scene, os.path.join(work, "m1.pfm"), spp, 1, threads)
    mf2, t2 = cc.matfit_render(exe, scene, os.path.join(work, "m2.pfm"), spp, 2, threads)
    ms, t3 = cc.mitsuba_render(mi, dr, "scalar_rgb", xml, None, spp, 1, threads)
    ms2, t4 = cc.mitsuba_render(mi, dr, "scalar_rgb", xml, None, spp, 2, threads)
    if ms.shape != mf.shape:
        return {"error": f"image sizes differ: Mitsuba {ms.shape}, matfit {mf.shape}"}
    rows = []
    for g, mask in sorted(cc.eroded_masks(ids).items()):
        n = int(mask.sum())
        if n < 30:
            continue
        a = (mf[mask].mean(0) + mf2[mask].mean(0)) / 2
        b = (ms[mask].mean(0) + ms2[mask].mean(0)) / 2
        rel = cc.rel_diff(a, b)
        ref = np.where(b > 0.02 * b.max(), b, max(b.max(), 1e-12))
        sigma = np.hypot(cc.mean_se(mf, mf2, mask), cc.mean_se(ms, ms2, mask)) / ref
        ok = bool((np.abs(rel) <= tol + 3 * sigma).all())
        rows.append((names[g], n, float(np.abs(rel).max()), float(sigma.max()), ok))
    whole = cc.rel_diff((mf + mf2).mean((0, 1)), (ms + ms2).mean((0, 1)))
    return {"rows": rows, "image": float(np.abs(whole).max()), "seconds": t1 + t2 + t3 + t4}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cache", default=os.path.expanduser("~/.cache/matfit-import-public"))
    ap.add_argument("--mirrors", default=os.environ.get("MATFIT_MIRRORS"),
                    help="folder of local bare mirrors OWNER+NAME/repo, used when present "
                    "[default: $MATFIT_MIRRORS; else git clone]")
    ap.add_argument("--matfit", help="matfit binary (default: $MATFIT, $CARGO_TARGET_DIR)")
    ap.add_argument("--only", help="comma-separated scene names")
    ap.add_argument("--width", type=int, default=96, help="render width (aspect kept)")
    ap.add_argument("--spp", type=int, default=32)
    ap.add_argument("--threads", type=int, default=os.cpu_count() or 2)
    ap.add_argument("--tol", type=float, default=0.02)
    ap.add_argument("--mitsuba-filter", choices=["box", "xml"], default="box",
                    help="Mitsuba's pixel filter: a box, matfit's, or the XML's own")
    ap.add_argument("--md", help="write the table, command and machine to this Markdown file")
    args = ap.parse_args()

    import drjit as dr
    import mitsuba as mi
    mi.set_variant("scalar_rgb")
    mi.set_log_level(mi.LogLevel.Error)
    exe = cc.find_matfit(args.matfit)
    if not os.path.exists(exe):
        sys.exit("no matfit binary")
    only = set(args.only.split(",")) if args.only else None
    t_start = time.perf_counter()
    load_before = os.getloadavg()
    results = []
    for name, repo, xml_rel, folders in SCENES:
        if only and name not in only:
            continue
        dest = os.path.join(args.cache, "scenes", name)
        shutil.rmtree(dest, ignore_errors=True)
        os.makedirs(dest)
        notes = []
        if repo is None:
            xml = write_oldformat(dest, mi)
            notes.append("stand-in written by this script (Mitsuba 0.5 idiom)")
            source = "stand-in"
        else:
            gd = git_dir(repo, args.mirrors, args.cache)
            source = f"{repo}:{xml_rel}"
            if gd is None:
                results.append(dict(name=name, source=source, mitsuba="—", matfit="—",
                                    notes=["repository not reachable from here"]))
                continue
            missing = extract(gd, folders, dest)
            xml = os.path.join(dest, xml_rel)
            if missing:
                notes += stand_ins(xml, [os.path.join(dest, p) for p in missing], mi)
        print(f"== {name}", flush=True)
        # What Mitsuba 3 does with the XML as published, then with Mitsuba-0.5-only bits fixed.
        ok, _, err = mitsuba_load(mi, xml, fix=False)
        fixed = []
        if not ok:
            ok, fixed, err2 = mitsuba_load(mi, xml, fix=True)
            err = err if not ok else err
        # Mitsuba's message without its source location and the scene's path.
        short = re.sub(r"\[[\w.]+:\d+\] ", "", err or "")
        short = short.replace(os.path.dirname(xml) + "/", "")[:140]
        if ok and not fixed:
            mitsuba = "yes"
        elif ok:
            mitsuba = "yes, after: " + "; ".join(fixed) + f" (as published: {short})"
        else:
            mitsuba = f"no: {short}"
        out = os.path.join(dest, "matfit")
        os.makedirs(out, exist_ok=True)
        r = run([exe, "import", "mitsuba", xml, "-o", os.path.join(out, "scene.toml")])
        warnings = [l for l in r.stderr.splitlines() if l.startswith("warning:")]
        if r.returncode == 0:
            matfit = f"yes ({len(warnings)} warnings)"
        else:
            errs = []
            for l in r.stderr.splitlines()[1:]:
                if not l.startswith("  "):
                    break
                errs.append(l.strip())
            errs = errs[:4] + ([f"… {len(errs) - 4} more"] if len(errs) > 4 else [])
            first = r.stderr.strip().splitlines()[0] if r.stderr.strip() else "?"
            matfit = "no: " + ("; ".join(re.sub(r"^\S+:(\d+): ", r"line \1: ", e)
                                         for e in errs) or first)
        res = dict(name=name, source=source, mitsuba=mitsuba, matfit=matfit, notes=notes,
                   warnings=warnings)
        if ok and r.returncode == 0:
            size = small_film(xml, args.width, args.mitsuba_filter == "box")
            if size:
                work = os.path.join(dest, "compare")
                os.makedirs(work, exist_ok=True)
                try:
                    res["cmp"] = compare(exe, mi, dr, xml, work, args.spp, args.threads,
                                         args.tol)
                    res["size"] = size
                    rows = (res["cmp"] or {}).get("rows", [])
                    notes += [EXPLAINED[(name, g)] for g, _, _, _, ok in rows
                              if not ok and (name, g) in EXPLAINED]
                except Exception as e:  # noqa: BLE001
                    res["cmp"] = {"error": str(e).splitlines()[0][:200]}
            else:
                notes.append("film size not found: not compared")
        results.append(res)
        c = res.get("cmp") or {}
        print(f"   Mitsuba: {mitsuba[:120]}\n   matfit: {matfit[:200]}\n   "
              f"{len([x for x in c.get('rows', []) if x[4]])}/{len(c.get('rows', []))} groups "
              f"within tol {c.get('error', '')}", flush=True)
        for g, n, rel, sigma, ok in c.get("rows", []):
            print(f"     {g:20s} {n:6d} px  |rel| {rel:6.1%}  σ {sigma:5.1%}  "
                  f"{'ok' if ok else 'outside'}", flush=True)
    total = time.perf_counter() - t_start
    load_after = os.getloadavg()

    n_mi = sum(1 for r in results if r["mitsuba"].startswith("yes"))
    n_fixed = sum(1 for r in results if r["mitsuba"].startswith("yes, after"))
    n_mf = sum(1 for r in results if r["matfit"].startswith("yes"))
    n_both = sum(1 for r in results if "cmp" in r and "rows" in (r["cmp"] or {}))
    n_agree = sum(1 for r in results if "cmp" in r and "rows" in (r["cmp"] or {})
                  and all(x[4] for x in r["cmp"]["rows"]))
    lines = ["| scene | source | Mitsuba 3 loads | matfit imports | groups within "
             f"{args.tol:.0%} + 3σ | worst group (|rel|, σ) | whole image |rel| | notes |",
             "|---|---|---|---|---|---|---|---|"]
    for r in results:
        c = r.get("cmp") or {}
        if "rows" in c:
            good = sum(1 for x in c["rows"] if x[4])
            worst = max(c["rows"], key=lambda x: x[2] / max(args.tol + 3 * x[3], 1e-9),
                        default=None)
            within = f"{good}/{len(c['rows'])}"
            worst_s = f"{worst[0]} {worst[2]:.1%} (σ {worst[3]:.1%})" if worst else "—"
            image = f"{c['image']:.1%}"
        else:
            within, worst_s, image = "—", c.get("error", "—"), "—"
        esc = lambda s: s.replace("|", "\\|")  # noqa: E731
        lines.append(f"| {r['name']} | {esc(r['source'])} | {esc(r['mitsuba'])} | "
                     f"{esc(r['matfit'])} | {within} | {esc(worst_s)} | {image} | "
                     f"{esc('; '.join(r['notes'])) or ''} |")
    table = "\n".join(lines)
    summary = (f"{len(results)} scenes: Mitsuba 3 loads {n_mi} ({n_fixed} of them only after "
               f"removing what Mitsuba 3 no longer reads), matfit imports {n_mf}; {n_both} "
               f"compared, {n_agree} with every group within {args.tol:.0%} + 3σ; {total:.0f} s")
    print(table + "\n\n" + summary)
    if args.md:
        mf_version = run([exe, "--version"]).stdout.strip()
        commit = run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"]).stdout.strip()
        details = []
        for r in results:
            c = r.get("cmp") or {}
            if "rows" in c:
                bad = [x for x in c["rows"] if not x[4]]
                if bad:
                    details.append(f"- {r['name']}: outside the tolerance: " + ", ".join(
                        f"{x[0]} {x[2]:.1%} (σ {x[3]:.1%}, {x[1]} px)" for x in bad[:12]) +
                        (" …" if len(bad) > 12 else ""))
            w = r.get("warnings") or []
            if w:
                kinds = {}
                for l in w:
                    k = re.sub(r"^warning: \S+:\d+: ", "", l)
                    k = k.replace(os.path.expanduser("~"), "~")
                    k = re.sub(r"\d+(\.\d+)?", "N", k)[:150]
                    kinds[k] = kinds.get(k, 0) + 1
                top = sorted(kinds.items(), key=lambda kv: -kv[1])
                details.append(f"- {r['name']} import warnings ({len(w)}): " + "; ".join(
                    f"{n}× “{k}”" for k, n in top))
        kept = ""
        if os.path.exists(args.md):
            old = open(args.md).read()
            if INVESTIGATIONS in old:
                kept = "\n" + old[old.index(INVESTIGATIONS):]
        with open(args.md, "w") as f:
            f.write(f"""# Import check over public scenes (issue 80)

Made by `bench/import_public.py` (its docstring says what each column means):

```sh
bash bench/setup_mitsuba.sh && source bench/mitsuba_env.sh
python bench/import_public.py {' '.join(sys.argv[1:])}
```

- date: {datetime.datetime.now().astimezone().strftime('%Y-%m-%d %H:%M %Z')}
- machine: {cc.machine()}; load average before {load_before[0]:.2f}, after
  {load_after[0]:.2f} (other builds shared the machine)
- matfit: {mf_version} (commit {commit}); Mitsuba {mi.__version__} (`scalar_rgb`), Dr.Jit
  {dr.__version__}, Python {platform.python_version()}
- renders: {args.width} px wide, {args.spp} spp × 2 seeds per renderer, Mitsuba's pixel filter
  {"a box (matfit's; the XML's own is named in the warnings)" if args.mitsuba_filter == "box"
   else "the XML's own"}; a group passes when
  every channel of its mean has |rel| ≤ {args.tol:.0%} + 3σ (σ from the seed-to-seed
  differences). "whole image" is the largest channel's |rel| of the image mean.
- scenes are fetched into {args.cache.replace(os.path.expanduser("~"), "~")} (not committed); stand-ins are listed under notes,
  and so are the causes of groups outside the tolerance where they are established.

{summary}.

{table}

Groups outside the tolerance are those whose materials matfit approximates, or that are lit
through one: each scene's import warnings (all kinds, most frequent first) name them below,
e.g. a `roughconductor` with eta/k with its Fresnel term frozen at normal incidence, a smooth
`plastic` under matfit's narrowest rough coat (α 0.005), `dielectric` glass as opaque diffuse
0.5 (which also darkens what Mitsuba lights through it), a `mask` made opaque (likewise), bump
maps dropped.

Details:

{chr(10).join(details) or 'none'}
{kept}""")
    return 0


if __name__ == "__main__":
    sys.exit(main())
