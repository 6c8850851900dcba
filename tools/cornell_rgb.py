#!/usr/bin/env python3
"""Measured Cornell box spectra (shared/data/cornell-box/cbox.xml) -> linear sRGB.

    bash bench/setup_mitsuba.sh && source bench/mitsuba_env.sh
    python tools/cornell_rgb.py [--xml PATH] [--no-mitsuba]

Linear sRGB here means ITU-R BT.709 primaries with a D65 white point, no transfer curve.

Data sources (nothing is downloaded at run time):
  * CIE 1931 2-degree colour-matching functions, 360-830 nm at 1 nm, and the CIE D65 relative
    spectral power distribution (300-780 nm at 5 nm): tables shipped inside the PyPI package
    `colour-science` 0.4.7 (colour.MSDS_CMFS['CIE 1931 2 Degree Standard Observer'] and
    colour.SDS_ILLUMINANTS['D65']; colour takes them from the CIE / CVRL tables).
  * XYZ -> linear sRGB: colour.RGB_COLOURSPACES['sRGB'].matrix_XYZ_to_RGB (the IEC 61966-2-1
    matrix, 3.2406 -1.5372 -0.4986 / -0.9689 1.8758 0.0415 / 0.0557 -0.2040 1.0570).
  * Optional: Mitsuba 3's own RGB-mode conversion, queried from the installed `mitsuba` package.

Spectra are piecewise linear between the given samples and zero outside [first, last]
wavelength (this is what Mitsuba's spectrum_list_to_srgb does too). Integrals are
trapezoidal sums on a 1 nm grid.

Methods
  D65      reflectance R:  XYZ = int R D65 cmf / int D65 ybar   (ybar, D65 over 360-830 nm)
           i.e. the colour of the paint under D65, scaled so that a perfect white reflector
           gives Y = 1 -> RGB ~ (1, 1, 1). This is the convention of Mitsuba 3's RGB variants
           for a <spectrum> that is not inside an emitter.
  L-ratio  reflectance R under the Cornell light's own spectrum L:
           rgb_c = [M int R L cmf]_c / [M int L cmf]_c   (c = r, g, b; M = XYZ->sRGB)
           A perfect white reflector maps to exactly (1, 1, 1), and for light that has bounced
           once off the paint an RGB renderer's product L_rgb * R_rgb equals the sRGB of the
           true spectral product L(lambda) R(lambda) exactly.
  emission L:      XYZ = int L cmf / int ybar   (ybar over 360-830 nm)
           i.e. Y is the ybar-weighted mean of L; this is Mitsuba's RGB-mode conversion of an
           emitter <spectrum> and matches what its spectral variants write to the film.
"""
import argparse
import os
import re
import sys
import warnings

import numpy as np

warnings.filterwarnings("ignore", message=".*Matplotlib.*")
import colour  # noqa: E402  (after the warning filter)

HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT_XML = os.path.normpath(os.path.join(HERE, "..", "..", "shared", "data", "cornell-box",
                                            "cbox.xml"))

GRID = np.arange(360.0, 831.0, 1.0)                  # nm, the CIE table's own grid
_CMFS = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
CMF = np.stack([np.interp(GRID, _CMFS.wavelengths, _CMFS.values[:, i]) for i in range(3)], 1)
_D65 = colour.SDS_ILLUMINANTS["D65"]
D65 = np.interp(GRID, _D65.wavelengths, _D65.values)   # 300-780 nm table; zero-order past 780
XYZ_TO_SRGB = np.asarray(colour.RGB_COLOURSPACES["sRGB"].matrix_XYZ_to_RGB, dtype=float)


def integrate(f):
    """Trapezoidal integral over GRID of f (N,) or (N, k)."""
    return np.trapezoid(f, GRID, axis=0) if hasattr(np, "trapezoid") else np.trapz(f, GRID, axis=0)


def sample(spec):
    """Piecewise-linear spectrum [(nm, value), ...] on GRID, zero outside its range."""
    w = np.array([p[0] for p in spec])
    v = np.array([p[1] for p in spec])
    out = np.interp(GRID, w, v)
    out[(GRID < w[0]) | (GRID > w[-1])] = 0.0
    return out


def refl_d65(spec):
    s = sample(spec)
    xyz = integrate(CMF * (s * D65)[:, None]) / integrate(CMF[:, 1] * D65)
    return XYZ_TO_SRGB @ xyz


def refl_under(spec, illum):
    s, l = sample(spec), sample(illum)
    num = XYZ_TO_SRGB @ integrate(CMF * (s * l)[:, None])
    den = XYZ_TO_SRGB @ integrate(CMF * l[:, None])
    return num / den


def emission(spec):
    return XYZ_TO_SRGB @ (integrate(CMF * sample(spec)[:, None]) / integrate(CMF[:, 1]))


def parse_cbox(path):
    xml = open(path).read()

    def pairs(s):
        return [tuple(float(x) for x in p.split(":")) for p in s.split(",")]

    refl = {k: pairs(v) for k, v in re.findall(
        r'<bsdf type="diffuse" id="(\w+)">\s*<spectrum name="reflectance" value="([^"]+)"', xml)}
    rad = pairs(re.search(r'<spectrum name="radiance" value="([^"]+)"', xml).group(1))
    return refl, rad


def mitsuba_rgb(refl, rad):
    """What Mitsuba 3's scalar_rgb variant itself makes of the spectra (None if unavailable)."""
    try:
        import mitsuba as mi
    except ImportError:
        return None
    mi.set_variant("scalar_rgb")
    mi.set_log_level(mi.LogLevel.Error)
    out = {}
    for name, spec in refl.items():
        b = mi.load_dict({"type": "diffuse",
                          "reflectance": {"type": "spectrum", "value": spec}})
        out[name] = np.array(mi.traverse(b)["reflectance.value"], dtype=float)
    e = mi.load_dict({"type": "rectangle",
                      "emitter": {"type": "area", "radiance": {"type": "spectrum", "value": rad}}})
    out["emission"] = np.array(mi.traverse(e)["emitter.radiance.value"], dtype=float)
    out["_version"] = mi.__version__
    return out


def fmt(c):
    return "(" + ", ".join(f"{x:.4f}" for x in c) + ")"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--xml", default=DEFAULT_XML)
    ap.add_argument("--no-mitsuba", action="store_true", help="skip querying Mitsuba")
    args = ap.parse_args()

    refl, rad = parse_cbox(args.xml)
    names = [n for n in ("white", "red", "green", "light") if n in refl]
    mit = None if args.no_mitsuba else mitsuba_rgb(refl, rad)

    print(f"CIE 1931 2deg CMFs + D65 from colour-science {colour.__version__}; "
          f"Mitsuba {mit['_version'] if mit else 'not queried'}")
    hdr = "| quantity | CIE, D65 (Mitsuba convention) | CIE, under light L (L-ratio) |"
    sep = "|---|---|---|"
    if mit:
        hdr += " Mitsuba 3 scalar_rgb | max abs diff D65 vs Mitsuba |"
        sep += "---|---|"
    print(hdr)
    print(sep)
    for n in names:
        a, b = refl_d65(refl[n]), refl_under(refl[n], rad)
        row = f"| {n} reflectance | {fmt(a)} | {fmt(b)} |"
        if mit:
            row += f" {fmt(mit[n])} | {np.abs(a - mit[n]).max():.1e} |"
        print(row)
    e = emission(rad)
    row = f"| light emission | {fmt(e)} | (same) |"
    if mit:
        row += f" {fmt(mit['emission'])} | {np.abs(e - mit['emission']).max():.1e} |"
    print(row)
    y = colour.RGB_COLOURSPACES["sRGB"].matrix_RGB_to_XYZ[1] @ e
    print(f"\nemission luminance Y = {y:.4f}; chromaticity of L: "
          f"xy = {fmt(colour.XYZ_to_xy(integrate(CMF * sample(rad)[:, None])))}")
    print("perfect white (R = 1 on 400-700 nm): D65 ->", fmt(refl_d65([(400, 1), (700, 1)])),
          " L-ratio ->", fmt(refl_under([(400, 1), (700, 1)], rad)))
    print("\nrecommended for matfit scenes/cornell and the Mitsuba cross-check "
          "(reflectances: L-ratio; emission: CIE):")
    for n in names:
        r = refl_under(refl[n], rad)
        print(f'  <rgb name="reflectance" value="{r[0]:.4f}, {r[1]:.4f}, {r[2]:.4f}"/>  <!-- {n} -->')
    print(f'  <rgb name="radiance" value="{e[0]:.4f}, {e[1]:.4f}, {e[2]:.4f}"/>  <!-- light -->')
    return 0


if __name__ == "__main__":
    sys.exit(main())
