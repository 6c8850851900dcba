#!/usr/bin/env python3
"""Recover rooms whose materials are not Ward (issues 20 and 26): Mitsuba 3 renders the photo
with its own BSDFs, matfit recovers it blind, and the recovery is scored by what it predicts.

    bash bench/setup_mitsuba.sh && source bench/mitsuba_env.sh
    python bench/nonward.py [--matfit PATH] [--spp 256] [--width 256] [--md FILE]

The room is scenes/figure6 with a diffuse floor (rho_d 0.5); the two blocks get Mitsuba BSDFs
that no Ward lobe reproduces exactly (the cases below). Mitsuba loads the XML written by
`matfit export mitsuba` with the blocks' BSDFs replaced, renders the photo (llvm_ad_rgb, box
filter, same camera and max_depth), and `matfit recover` fits it with exposure 1, twice: with
the whole hierarchy, and with `--no-microfacet` (the Ward lobes alone, as before level 8).

Prediction: the truth (Mitsuba) and each recovered scene (matfit's own renderer, exact for its
own models) are rendered from a new viewpoint and, from the photo's viewpoint, with the light
moved; per group, the mean over pixels at least 2 px inside the group (matfit's index buffer)
is compared, the largest channel's relative difference. Printed per group: level, status, eps
and its noise floor, the parameters, and the two predictions. Exit status 1 if any group ends
`analysing`.
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
from crosscheck import (eroded_masks, figure6_variant, find_matfit, group_names,  # noqa: E402
                        mitsuba_render, read_pfm)

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


def replace_bsdf(xml, group, bsdf):
    """Replaces the BSDF of `group` (the exporter writes one `twosided` BSDF per group, with the
    group's name as its id, which the group's shapes reference)."""
    pat = re.compile(r'<bsdf type="twosided" id="%s">.*?\n    </bsdf>' % re.escape(group), re.S)
    xml, n = pat.subn(lambda m: f'<bsdf type="twosided" id="{group}">\n{bsdf}\n    </bsdf>', xml)
    assert n == 1, f"group {group} not found once in the exported XML"
    return xml


# The new viewpoint (right of and below the photo's, looking across both blocks) and the moved
# light (from the back of the ceiling to its middle, right of centre).
NOVEL_VIEW = ("eye = [1.5, 1.2, -1.2]", "target = [-0.4, 0.5, -4.4]")
LIGHT_CORNER = ("corner = [-0.5, 2.99, -6.6]", "corner = [0.4, 2.99, -4.2]")


def prediction_scene(text, kind):
    """The scene text seen from the new viewpoint ("view") or with the light moved ("light")."""
    if kind == "view":
        text, n1 = re.subn(r"^eye = \[.*\]$", NOVEL_VIEW[0], text, count=1, flags=re.M)
        text, n2 = re.subn(r"^target = \[.*\]$", NOVEL_VIEW[1], text, count=1, flags=re.M)
        assert n1 == n2 == 1, "figure6's camera lines changed"
    else:
        assert text.count(LIGHT_CORNER[0]) == 1, "figure6's light changed"
        text = text.replace(*LIGHT_CORNER)
    return text


def write(path, text):
    with open(path, "w") as f:
        f.write(text)
    return path


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--matfit", default=None)
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--width", type=int, default=256)
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--cases", default=",".join(CASES), help="comma-separated case names")
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
    for case in args.cases.split(","):
        bsdfs = CASES[case]
        d = os.path.join(work, case)
        os.makedirs(d)
        scene = figure6_variant(d, '{ type = "diffuse", rho_d = 0.5 }', width, height)
        base_text = open(scene).read()

        def truth_render(text, name):
            """Mitsuba's render of the true room described by `text` (the blocks' BSDFs
            replaced in matfit's export)."""
            sd = os.path.join(d, name)
            os.makedirs(sd, exist_ok=True)
            st = write(os.path.join(sd, "scene.toml"), text)
            mi_dir = os.path.join(sd, "mitsuba")
            subprocess.run([exe, "export", "mitsuba", st, "-o", mi_dir], check=True,
                           capture_output=True)
            xml_path = os.path.join(mi_dir, "scene.xml")
            xml = open(xml_path).read()
            for shape, bsdf in bsdfs.items():
                xml = replace_bsdf(xml, shape, bsdf)
            img, t = mitsuba_render(mi, dr, "llvm_ad_rgb", xml_path, xml, args.spp, 1, threads)
            return img, t

        img, t_render = truth_render(base_text, "photo")
        photo = os.path.join(d, "photo.exr")
        mi.util.write_bitmap(photo, img.astype(np.float32), write_async=False)
        truths = {k: truth_render(prediction_scene(base_text, k), "truth-" + k)[0]
                  for k in ("view", "light")}
        names = group_names(exe, scene)
        masks = {}
        for k in ("view", "light"):
            st = write(os.path.join(d, f"ids-{k}.toml"), prediction_scene(base_text, k))
            ids_path = os.path.join(d, f"ids-{k}.pfm")
            subprocess.run([exe, "render", st, "-o", ids_path, "--aov", "group"], check=True,
                           capture_output=True)
            masks[k] = eroded_masks(read_pfm(ids_path)[..., 0].astype(np.int64))
        for label, extra in (("whole hierarchy", []), ("--no-microfacet", ["--no-microfacet"])):
            t0 = time.perf_counter()
            rec = os.path.join(d, "recovery" + ("-ward" if extra else ""))
            r = subprocess.run([exe, "recover", scene, photo, "-o", rec, "--exposure", "1"]
                               + extra, capture_output=True, text=True)
            t_rec = time.perf_counter() - t0
            if r.returncode != 0:
                sys.exit(f"{case}: matfit recover failed:\n{r.stdout}\n{r.stderr}")
            res = json.load(open(os.path.join(rec, "results.json")))
            rec_text = open(os.path.join(rec, "recovered.toml")).read()
            pred = {}
            for k in ("view", "light"):
                st = write(os.path.join(rec, f"pred-{k}.toml"), prediction_scene(rec_text, k))
                out = os.path.join(rec, f"pred-{k}.pfm")
                subprocess.run([exe, "render", st, "-o", out, "--spp", str(args.spp)],
                               check=True, capture_output=True)
                pred[k] = read_pfm(out)
            out_lines.append(f"### {case}, {label}\n")
            out_lines.append(
                f"Mitsuba photo {width}x{height} at {args.spp} spp in {t_render:.1f} s; matfit "
                f"recover {t_rec:.1f} s, {res['iterations']} iterations. Prediction: per group "
                f"mean, largest channel's |relative difference| to Mitsuba's render of the "
                f"truth, new viewpoint / moved light.\n")
            out_lines.append("| group | level | status | eps | noise floor | parameters "
                             "| new view | moved light |")
            out_lines.append("|---|---|---|---:|---:|---|---:|---:|")
            for g in res["groups"]:
                if g["status"] in ("light",):
                    continue
                p = g.get("params", {})
                ps = ", ".join(
                    f"{k} " + (("(" + ", ".join(f"{x:.3f}" for x in v) + ")")
                               if isinstance(v, list) else f"{v:.3f}") for k, v in p.items())
                eps = g.get("error")
                nf = g.get("noise_floor")
                gi = names.index(g["name"]) if g["name"] in names else None
                cells = []
                for k in ("view", "light"):
                    m = masks[k].get(gi) if gi is not None else None
                    if m is None or m.sum() < 20:
                        cells.append("")
                        continue
                    a, b = pred[k][m].mean(0), truths[k][m].mean(0)
                    ok = b > 0.02 * b.max()
                    cells.append(f"{100 * np.abs((a - b)[ok] / b[ok]).max():.1f}%")
                out_lines.append(
                    f"| {g['name']} | {g['level']} | {g['status']} | "
                    f"{'' if eps is None else f'{eps:.4f}'} | "
                    f"{'' if nf is None else f'{nf:.4f}'} | {ps} | {cells[0]} | {cells[1]} |")
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
