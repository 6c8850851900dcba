#!/usr/bin/env python3
"""Which RGB set reproduces Mitsuba's *spectral* render of cbox.xml best?

Renders cbox.xml with llvm_ad_spectral (ground truth: the measured spectra), then renders
copies of the XML whose spectra are replaced by <rgb> values (llvm_ad_rgb) for each RGB set
that tools/cornell_rgb.py computes, and compares image means and wall-region means.

    source bench/mitsuba_env.sh
    python bench/cornell_spectral_vs_rgb.py [--res 128] [--spp 256] [--out bench/out]
"""
import argparse
import os
import re
import sys
import time

import drjit as dr
import mitsuba as mi
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tools"))
import cornell_rgb as cr  # noqa: E402

XML = cr.DEFAULT_XML


def rgb_xml(xml, refl_rgb, emit_rgb):
    """cbox.xml text with each diffuse <spectrum> and the radiance <spectrum> replaced by <rgb>."""
    def sub_bsdf(m):
        r = refl_rgb[m.group(1)]
        return (f'<bsdf type="diffuse" id="{m.group(1)}">\n        <rgb name="reflectance" '
                f'value="{r[0]:.6f}, {r[1]:.6f}, {r[2]:.6f}"/>')
    xml = re.sub(r'<bsdf type="diffuse" id="(\w+)">\s*<spectrum name="reflectance" value="[^"]+"/>',
                 sub_bsdf, xml)
    e = emit_rgb
    xml = re.sub(r'<spectrum name="radiance" value="[^"]+"/>',
                 f'<rgb name="radiance" value="{e[0]:.6f}, {e[1]:.6f}, {e[2]:.6f}"/>', xml)
    assert "<spectrum" not in xml
    return xml


def render(variant, xml_text, res, spp, seed=0):
    mi.set_variant(variant)
    mi.set_log_level(mi.LogLevel.Error)
    dr.set_thread_count(os.cpu_count() or 2)
    # load_string resolves meshes/ relative to the file resolver: add the scene folder.
    mi.file_resolver().prepend(os.path.dirname(XML))
    scene = mi.load_string(xml_text, optimize=False, res=res, spp=spp)
    t0 = time.perf_counter()
    img = np.array(mi.render(scene, seed=seed), dtype=float)[..., :3]
    return img, time.perf_counter() - t0


def regions(res):
    """Pixel boxes (y0, y1, x0, x1) as fractions of the image, hand-picked for cbox's camera."""
    f = {"red wall": (0.30, 0.60, 0.02, 0.08), "green wall": (0.30, 0.60, 0.92, 0.98),
         "back wall": (0.20, 0.35, 0.55, 0.75), "floor (front)": (0.92, 0.99, 0.40, 0.60),
         "ceiling": (0.01, 0.07, 0.15, 0.35)}
    return {k: tuple(int(round(v * res)) for v in b) for k, b in f.items()}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--out", default=os.path.join(HERE, "out"))
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)

    xml = open(XML).read()
    refl, rad = cr.parse_cbox(XML)
    emit = cr.emission(rad)
    sets = {
        "D65 (Mitsuba-style)": {n: cr.refl_d65(s) for n, s in refl.items()},
        "L-ratio": {n: cr.refl_under(s, rad) for n, s in refl.items()},
    }

    imgs = {}
    imgs["spectral (truth)"], t = render("llvm_ad_spectral", xml, args.res, args.spp)
    print(f"llvm_ad_spectral render: {t:.2f}s")
    imgs["Mitsuba RGB of spectra"], t = render("llvm_ad_rgb", xml, args.res, args.spp)
    print(f"llvm_ad_rgb render (spectra converted by Mitsuba): {t:.2f}s")
    for name, r in sets.items():
        imgs[name], t = render("llvm_ad_rgb", rgb_xml(xml, r, emit), args.res, args.spp)
        print(f"llvm_ad_rgb render ({name}): {t:.2f}s")

    for name, img in imgs.items():
        fn = re.sub(r"[^a-z0-9]+", "_", name.lower()).strip("_")
        mi.util.write_bitmap(os.path.join(args.out, f"cbox_{fn}.exr"), img.astype(np.float32),
                            write_async=False)  # async EXR writes hang at exit
        mi.util.write_bitmap(os.path.join(args.out, f"cbox_{fn}.png"), img.astype(np.float32),
                            write_async=False)  # async EXR writes hang at exit

    gt = imgs["spectral (truth)"]
    regs = regions(args.res)
    print("\nmean linear RGB per region; err = (rgb - spectral) / max channel of spectral, per channel")
    score = {}
    for name, img in imgs.items():
        print(f"  {name}:")
        for rn, (y0, y1, x0, x1) in [("image", (0, args.res, 0, args.res))] + list(regs.items()):
            m = img[y0:y1, x0:x1].reshape(-1, 3).mean(0)
            g = gt[y0:y1, x0:x1].reshape(-1, 3).mean(0)
            rel = (m - g) / max(g.max(), 1e-9)
            score.setdefault(name, []).append(np.abs(rel).max())
            print(f"    {rn:14s} {cr.fmt(m)}  err {'  '.join(f'{x:+.3f}' for x in rel)}")
    print("\nworst |err| over regions:  " +
          ";  ".join(f"{k}: {max(v):.3f}" for k, v in score.items() if k != "spectral (truth)"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
