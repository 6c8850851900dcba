#!/usr/bin/env python3
"""Recover rooms whose materials are not Ward (issue 26): Mitsuba 3 renders the photo with its own
BSDFs, matfit recovers it blind, and every group must end decided (none `analysing`).

    bash bench/setup_mitsuba.sh && source bench/mitsuba_env.sh
    python bench/nonward.py [--matfit PATH] [--spp 256] [--width 256] [--md FILE]

The room is scenes/figure6 with a diffuse floor (rho_d 0.5); the two blocks get Mitsuba BSDFs
that no Ward lobe reproduces exactly (the cases below). Mitsuba loads the XML written by
`matfit export mitsuba` with the blocks' BSDFs replaced, renders the photo (llvm_ad_rgb, box
filter, same camera and max_depth), and `matfit recover` fits it with exposure 1. Printed per
group: level, status, eps and its noise floor, and the parameters. Exit status 1 if any group
ends `analysing`.
"""
import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.normpath(os.path.join(HERE, ".."))
sys.path.insert(0, HERE)
from crosscheck import figure6_variant, find_matfit, mitsuba_render  # noqa: E402

CASES = {
    # A red plastic with a GGX coat, and a rough green metal.
    "ggx-plastic+conductor": {
        "big_block": """<bsdf type="roughplastic">
            <string name="distribution" value="ggx"/>
            <float name="alpha" value="0.1"/>
            <rgb name="diffuse_reflectance" value="0.7, 0.05, 0.05"/>
        </bsdf>""",
        "small_block": """<bsdf type="roughconductor">
            <string name="material" value="none"/>
            <string name="distribution" value="ggx"/>
            <float name="alpha" value="0.2"/>
            <rgb name="specular_reflectance" value="0.2, 0.7, 0.3"/>
        </bsdf>""",
    },
    # A Beckmann plastic, and a smooth plastic (a diffuse base under a mirror-like coat).
    "beckmann+smooth-plastic": {
        "big_block": """<bsdf type="roughplastic">
            <string name="distribution" value="beckmann"/>
            <float name="alpha" value="0.3"/>
            <rgb name="diffuse_reflectance" value="0.6, 0.3, 0.1"/>
        </bsdf>""",
        "small_block": """<bsdf type="plastic">
            <rgb name="diffuse_reflectance" value="0.1, 0.5, 0.6"/>
        </bsdf>""",
    },
}


def replace_bsdf(xml, shape_id, bsdf):
    pat = re.compile(r'(<shape type="ply" id="%s">\s*<string name="filename" value="[^"]+"/>\s*)'
                     r'<bsdf type="twosided">.*?</bsdf>\s*</bsdf>' % re.escape(shape_id), re.S)
    xml, n = pat.subn(lambda m: m.group(1) + bsdf, xml)
    assert n == 1, f"shape {shape_id} not found once in the exported XML"
    return xml


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--matfit", default=None)
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--width", type=int, default=256)
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--md", default=None, help="also write the tables to this Markdown file")
    args = ap.parse_args()
    import drjit as dr
    import mitsuba as mi

    exe = find_matfit(args.matfit)
    width, height = args.width, args.width * 3 // 4
    threads = args.threads or os.cpu_count()
    out_lines = []
    undecided = 0
    work = tempfile.mkdtemp(prefix="matfit-nonward-")
    for case, bsdfs in CASES.items():
        d = os.path.join(work, case)
        os.makedirs(d)
        scene = figure6_variant(d, '{ type = "diffuse", rho_d = 0.5 }', width, height)
        mi_dir = os.path.join(d, "mitsuba")
        subprocess.run([exe, "export", "mitsuba", scene, "-o", mi_dir], check=True,
                       capture_output=True)
        xml_path = os.path.join(mi_dir, "scene.xml")
        xml = open(xml_path).read()
        for shape, bsdf in bsdfs.items():
            xml = replace_bsdf(xml, shape, bsdf)
        img, t_render = mitsuba_render(mi, dr, "llvm_ad_rgb", xml_path, xml, args.spp, 1,
                                       threads)
        photo = os.path.join(d, "photo.exr")
        mi.util.write_bitmap(photo, img.astype(np.float32), write_async=False)
        t0 = time.perf_counter()
        rec = os.path.join(d, "recovery")
        r = subprocess.run([exe, "recover", scene, photo, "-o", rec, "--exposure", "1"],
                           capture_output=True, text=True)
        t_rec = time.perf_counter() - t0
        if r.returncode != 0:
            sys.exit(f"{case}: matfit recover failed:\n{r.stdout}\n{r.stderr}")
        res = json.load(open(os.path.join(rec, "results.json")))
        out_lines.append(f"### {case}\n")
        out_lines.append(f"Mitsuba photo {width}x{height} at {args.spp} spp in {t_render:.1f} s; "
                         f"matfit recover {t_rec:.1f} s, {res['iterations']} iterations.\n")
        out_lines.append("| group | level | status | eps | noise floor | parameters |")
        out_lines.append("|---|---|---|---:|---:|---|")
        for g in res["groups"]:
            if g["status"] in ("light",):
                continue
            p = g.get("params", {})
            ps = ", ".join(
                f"{k} " + (("(" + ", ".join(f"{x:.3f}" for x in v) + ")") if isinstance(v, list)
                           else f"{v:.3f}") for k, v in p.items())
            eps = g.get("error")
            nf = g.get("noise_floor")
            out_lines.append(
                f"| {g['name']} | {g['level']} | {g['status']} | "
                f"{'' if eps is None else f'{eps:.4f}'} | {'' if nf is None else f'{nf:.4f}'} "
                f"| {ps} |")
            undecided += g["status"] == "analysing"
        out_lines.append("")
    text = "\n".join(out_lines)
    print(text)
    print(f"outputs in {work}")
    if args.md:
        with open(args.md, "w") as f:
            f.write(f"# Non-Ward rooms (bench/nonward.py)\n\n{text}\n")
    if undecided:
        print(f"FAIL: {undecided} group(s) ended analysing")
        sys.exit(1)
    print("PASS: every group decided")


if __name__ == "__main__":
    main()
