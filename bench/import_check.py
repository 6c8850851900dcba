#!/usr/bin/env python3
"""Import check (issue 22): a Mitsuba 3 scene rendered by Mitsuba vs its import rendered by matfit.

    bash bench/setup_mitsuba.sh && source bench/mitsuba_env.sh
    python bench/import_check.py [--xml scenes/mitsuba-cbox/scene.xml] [--spp 256] [--md bench/IMPORT.md]

`matfit import mitsuba XML -o WORK/scene.toml` converts the scene (hand-written in Mitsuba's own
idiom: rectangles and cubes placed by transform chains, <default> parameters, BSDFs by reference,
a horizontal field of view); Mitsuba renders the XML itself, matfit renders the imported TOML,
both at the same spp and resolution (passed to both as the XML's parameters: -D for matfit's
import, load_file(**params) for Mitsuba). The acceptance of issue 22: every group's mean radiance
within 1% of Mitsuba's.

Groups, masks, noise and the verdict are crosscheck.py's (its helpers are reused): masks from
matfit's group index buffer eroded by 2 px, two seeds per renderer averaged, sigma the standard
error of the relative difference from both renderers' seed-to-seed pixel differences; a group
passes when every channel has |rel| <= tol + 3 sigma (--strict: <= tol). Exit status 1 on a FAIL.
"""
import argparse
import datetime
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import crosscheck as cc  # noqa: E402  (the shared helpers)

ROOT = cc.ROOT


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--xml", default=os.path.join(ROOT, "scenes", "mitsuba-cbox", "scene.xml"))
    ap.add_argument("--params", help="the XML's parameters instead of res_x/res_y from --res, "
                    "as NAME=VALUE,... (e.g. res=256 for shared/data/cornell-box/cbox.xml)")
    ap.add_argument("--spp", type=int, default=256, help="samples per pixel, both renderers")
    ap.add_argument("--res", default="256x192", help="resolution (the XML's $res_x, $res_y)")
    ap.add_argument("--matfit", help="matfit binary (default: $MATFIT, $CARGO_TARGET_DIR)")
    ap.add_argument("--variant", default="llvm_ad_rgb", help="Mitsuba variant (or scalar_rgb)")
    ap.add_argument("--threads", type=int, default=os.cpu_count() or 2)
    ap.add_argument("--tol", type=float, default=0.01)
    ap.add_argument("--strict", action="store_true", help="fail on |rel| > tol, noise or not")
    ap.add_argument("--out", help="keep images here (default: a temporary folder)")
    ap.add_argument("--md", help="also write the table, command and versions to this Markdown file")
    args = ap.parse_args()

    import drjit as dr
    import mitsuba as mi

    exe = cc.find_matfit(args.matfit)
    if args.variant.startswith("llvm") and not os.environ.get("DRJIT_LIBLLVM_PATH"):
        print("warning: DRJIT_LIBLLVM_PATH unset; source bench/mitsuba_env.sh", file=sys.stderr)
    work = args.out or tempfile.mkdtemp(prefix="matfit-import-check-")
    os.makedirs(work, exist_ok=True)
    w, h = (int(x) for x in args.res.split("x"))
    # The XML's $spp is not passed to Mitsuba: render(spp=...) sets it (and crosscheck's helper
    # takes spp itself).
    params = dict(res_x=w, res_y=h)
    if args.params:
        params = dict(kv.split("=", 1) for kv in args.params.split(","))

    scene = os.path.join(work, "scene.toml")
    cmd = [exe, "import", "mitsuba", args.xml, "-o", scene]
    for k, v in dict(params, spp=args.spp).items():
        cmd += ["-D", f"{k}={v}"]
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"matfit import failed:\n{r.stdout}{r.stderr}")
    import_warnings = [l for l in r.stderr.splitlines() if l.startswith("warning:")]
    for l in import_warnings:
        print(l)

    subprocess.run([exe, "render", scene, "--aov", "group", "-o", os.path.join(work, "ids.pfm")],
                   check=True)
    ids = np.rint(cc.read_pfm(os.path.join(work, "ids.pfm"))[..., 0]).astype(int)
    names = cc.group_names(exe, scene)
    seeds = (1, 2)
    t0 = time.perf_counter()
    mf, t_mf = cc.matfit_render(exe, scene, os.path.join(work, "matfit.pfm"), args.spp, seeds[0],
                                args.threads)
    mf2, t_mf2 = cc.matfit_render(exe, scene, os.path.join(work, "matfit_seed2.pfm"), args.spp,
                                  seeds[1], args.threads)
    ms, t_ms = cc.mitsuba_render(mi, dr, args.variant, args.xml, None, args.spp, seeds[0],
                                 args.threads, **params)
    ms2, t_ms2 = cc.mitsuba_render(mi, dr, args.variant, args.xml, None, args.spp, seeds[1],
                                   args.threads, **params)
    mi.util.write_bitmap(os.path.join(work, "mitsuba.exr"), ms.astype(np.float32),
                         write_async=False)
    assert ms.shape == mf.shape, f"Mitsuba {ms.shape} vs matfit {mf.shape}"

    rows, failed, noisy, worst = [], [], [], 0.0
    for g, mask in sorted(cc.eroded_masks(ids).items()):
        n = int(mask.sum())
        if n < 50:
            continue
        a = (mf[mask].mean(0) + mf2[mask].mean(0)) / 2
        b = (ms[mask].mean(0) + ms2[mask].mean(0)) / 2
        rel = cc.rel_diff(a, b)
        ref = np.where(b > 0.02 * b.max(), b, max(b.max(), 1e-12))
        sigma = np.hypot(cc.mean_se(mf, mf2, mask), cc.mean_se(ms, ms2, mask)) / ref
        worst = max(worst, np.abs(rel).max())
        allowed = args.tol + (0.0 if args.strict else 3.0 * sigma)
        status = "ok"
        if (np.abs(rel) > allowed).any():
            status = "FAIL"
            failed.append(names[g])
        elif (3.0 * sigma > args.tol).any():
            status = "noisy"
            noisy.append(names[g])
        rows.append((names[g], n, a, b, rel, sigma.max(), status))
    t_all = time.perf_counter() - t0

    def f3(v):
        return ", ".join(f"{x:.4f}" for x in v)

    lines = ["| group | pixels | matfit mean RGB | Mitsuba mean RGB | rel. diff (R, G, B) | σ | |",
             "|---|---:|---|---|---|---:|---|"]
    for name, n, a, b, rel, sigma, status in rows:
        lines.append(f"| {name} | {n} | {f3(a)} | {f3(b)} | "
                     f"{', '.join(f'{x:+.2%}' for x in rel)} | {sigma:.2%} | {status} |")
    table = "\n".join(lines)
    print(table)
    rule = f"|rel| ≤ {args.tol:.0%}" + ("" if args.strict else " + 3σ")
    verdict = (f"{'PASS' if not failed else 'FAIL'} ({rule}): worst |rel. diff| {worst:.2%}; "
               f"failed: {', '.join(failed) or 'none'}; noisy (3σ > {args.tol:.0%}): "
               f"{', '.join(noisy) or 'none'}; {w}×{h}, {args.spp} spp × 2 seeds; matfit "
               f"{t_mf + t_mf2:.1f} s, Mitsuba {t_ms + t_ms2:.1f} s; total {t_all:.0f} s")
    print("\n" + verdict)

    if args.md:
        mf_version = subprocess.run([exe, "--version"], capture_output=True,
                                    text=True).stdout.strip()
        commit = subprocess.run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"],
                                capture_output=True, text=True).stdout.strip()
        xml_rel = os.path.relpath(args.xml, ROOT)
        warn_text = "\n".join(f"  - `{l}`" for l in import_warnings) or "  none"
        with open(args.md, "w") as f:
            f.write(f"""# Import check: a Mitsuba scene vs its import (issue 22)

Made by `bench/import_check.py` (its docstring says how groups are compared):

```sh
source bench/mitsuba_env.sh
python bench/import_check.py {' '.join(sys.argv[1:])}
```

- scene: `{xml_rel}`, imported with `matfit import mitsuba`; import warnings:
{warn_text}
- date: {datetime.datetime.now().astimezone().strftime('%Y-%m-%d %H:%M %Z')}
- machine: {cc.machine()}
- matfit: {mf_version} (commit {commit}), `--threads {args.threads}`
- Mitsuba {mi.__version__} (`{args.variant}`), Dr.Jit {dr.__version__}, numpy {np.__version__},
  Python {platform.python_version()}
- rel. diff = (matfit − Mitsuba) / Mitsuba per channel of the group's mean; each renderer's two
  seeds ({seeds[0]}, {seeds[1]}) averaged; σ = standard error of rel. diff (max over channels).
  A group passes if every channel has {rule}.

{table}

{verdict}
""")
    if args.out is None:
        shutil.rmtree(work, ignore_errors=True)
    return 0 if not failed else 1


if __name__ == "__main__":
    sys.exit(main())
