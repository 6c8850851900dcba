#!/usr/bin/env python3
"""Writes the test scenes of the "decisions" measurements, truth known, in matfit's format and as
Mitsuba 3 BSDFs for the same scene (Python 3.11 + numpy; PNG through zlib):

    python scenes/interior/generate.py [interior|measured] [-o DIR] [--seed S]
        [--wallpaper-contrast C] [--matfit PATH]

(numpy is in bench/.venv: `bash bench/setup_mitsuba.sh && source bench/mitsuba_env.sh`; with
Mitsuba importable the measured room's truth also gets its BSDFs' albedos.)

`interior` (the default): a textured living room with a staircase, production-style:
  ≥ 200k triangles of real geometry (bevelled boxes for the sofa, the stair steps, the frames,
  the table; cylinders for balusters, legs, the lamp; two spheres), 27 material groups of which
  several are split across many meshes, a printed wallpaper (a repeating diamond pattern whose
  texel is a few photo pixels; `--wallpaper-contrast` sets the low-contrast wall's diamonds,
  default ±10%), a textured wood floor and stairs under a rough glossy coat (Mitsuba
  `roughplastic` with a bitmap diffuse_reflectance, α 0.12–0.15), rough white paint, brass and
  gold (`roughconductor`), a mirror, thin picture frames, three textured paintings, a rug, and
  a ceiling, beams and a front wall no camera pixel shows. Photo 480×270 and a novel viewpoint.
`measured`: a Cornell-box-like room whose blocks and one wall are Mitsuba materials that are not
  matfit's models (principled with sheen/clearcoat/specular tint, a blendbsdf of a rough
  conductor over a diffuse base, spectral-IOR Cu and Au conductors, `plastic` nonlinear); see
  the truth file for what is and is not defined there.

In DIR (default /tmp/matfit-scenes/<scene>) it writes:
  scene.toml          the scene in matfit's format (the true materials where matfit has them,
                      the nearest matfit material otherwise: `render` of it is NOT the truth
                      where the truth file says `exact_in_matfit: false`)
  scene_novel.toml    the same scene seen from the novel viewpoint
  meshes/*.ply        binary PLY meshes in world space, with normals and UVs
  textures/*.png      8-bit sRGB textures (matfit and Mitsuba both decode them to linear)
  mitsuba_bsdfs.json  group -> the Mitsuba 3 BSDF (XML, without `twosided`) that is the truth
  truth.json          per group: the true parameters in matfit's terms (rho_d RGB, rho_s, alpha,
                      texture), the Mitsuba BSDF, the objects; the cameras
  mitsuba/scene.xml, mitsuba/novel.xml   with --matfit (or a matfit found in the usual target
                      folders): `matfit export mitsuba` of the two scene files with every
                      group's BSDF replaced by its true one (so geometry, UVs, camera, lights
                      and the film are exactly matfit's), see `assemble_mitsuba`.
Deterministic: the same seed gives the same bytes.
"""
import argparse
import json
import os
import re
import shutil
import struct
import subprocess
import sys
import zlib

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.normpath(os.path.join(HERE, "..", ".."))

# The coat of matfit's `plastic` and of Mitsuba's `roughplastic` (int_ior 1.49, Mitsuba's
# default polypropylene, ext_ior 1.000277 air): reflectance at normal incidence.
ETA = 1.49
F0 = ((ETA - 1.0) / (ETA + 1.0)) ** 2


# ---------------------------------------------------------------------------------------------
# Files


def srgb_encode(x):
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def srgb_decode(c):
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, np.power((c + 0.055) / 1.055, 2.4))


def write_png(path, lin):
    """lin: (h, w, 3) linear reflectance, row 0 at the top. Returns the linear texels the file
    holds (after 8-bit sRGB quantisation), which are the truth."""
    code = np.round(srgb_encode(lin) * 255).astype(np.uint8)
    h, w, _ = code.shape
    raw = b"".join(b"\x00" + code[y].tobytes() for y in range(h))

    def chunk(tag, data):
        c = struct.pack(">I", len(data)) + tag + data
        return c + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
    png += chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b"")
    with open(path, "wb") as f:
        f.write(png)
    return srgb_decode(code / 255.0)


def read_png_linear(path):
    """The linear texels of an 8-bit RGB PNG written by write_png (filter 0 rows only)."""
    data = open(path, "rb").read()
    pos, idat, w, h = 8, b"", 0, 0
    while pos < len(data):
        n = struct.unpack(">I", data[pos:pos + 4])[0]
        tag = data[pos + 4:pos + 8]
        body = data[pos + 8:pos + 8 + n]
        if tag == b"IHDR":
            w, h = struct.unpack(">II", body[:8])
        elif tag == b"IDAT":
            idat += body
        pos += 12 + n
    raw = np.frombuffer(zlib.decompress(idat), dtype=np.uint8).reshape(h, 1 + 3 * w)
    assert (raw[:, 0] == 0).all(), "only unfiltered PNG rows are read here"
    return srgb_decode(raw[:, 1:].reshape(h, w, 3) / 255.0)


def write_ply(path, v, f, n=None, uv=None):
    v = np.asarray(v, np.float32)
    props = ["x", "y", "z"]
    cols = [v]
    if n is not None:
        props += ["nx", "ny", "nz"]
        cols.append(np.asarray(n, np.float32))
    if uv is not None:
        props += ["u", "v"]
        cols.append(np.asarray(uv, np.float32))
    vert = np.concatenate(cols, 1).astype("<f4")
    head = "ply\nformat binary_little_endian 1.0\n"
    head += f"element vertex {len(v)}\n" + "".join(f"property float {p}\n" for p in props)
    head += f"element face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n"
    faces = np.zeros(len(f), dtype=[("n", "u1"), ("i", "<i4", 3)])
    faces["n"] = 3
    faces["i"] = f
    with open(path, "wb") as fh:
        fh.write(head.encode())
        fh.write(vert.tobytes())
        fh.write(faces.tobytes())


# ---------------------------------------------------------------------------------------------
# Geometry: each function returns a mesh dict {v, f, n, uv} in local or world coordinates.


def grid_faces(nu, nv, base=0):
    """Two triangles per cell of an (nu+1) x (nv+1) vertex grid (row-major in v)."""
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="xy")
    a = base + j * (nu + 1) + i
    b, c, d = a + 1, a + nu + 1, a + nu + 2
    return np.concatenate([np.stack([a, b, d], -1).reshape(-1, 3),
                           np.stack([a, d, c], -1).reshape(-1, 3)])


def merge(*meshes):
    out = {"v": [], "f": [], "n": [], "uv": []}
    base = 0
    for m in meshes:
        out["v"].append(m["v"])
        out["f"].append(m["f"] + base)
        out["n"].append(m["n"])
        out["uv"].append(m["uv"])
        base += len(m["v"])
    return {k: np.concatenate(x) for k, x in out.items()}


def rounded_box(lo, hi, r, n, tile=1.0):
    """A box [lo, hi] with edges and corners rounded by radius r, each face an n x n grid (12 n²
    triangles). UVs: each face's planar coordinates in metres / tile (box projection)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    r = min(r, 0.49 * float((hi - lo).min()))
    ilo, ihi = lo + r, hi - r
    t = np.linspace(0.0, 1.0, n + 1)
    # Spread the grid so that the rounded strips get samples: map t through the box profile.
    meshes = []
    for axis in range(3):
        for side in (0, 1):
            a1, a2 = [k for k in range(3) if k != axis]
            if side == 0:
                a1, a2 = a2, a1  # keep the faces' winding outward
            s, q = np.meshgrid(t, t, indexing="xy")
            p = np.zeros(s.shape + (3,))
            p[..., a1] = lo[a1] + s * (hi[a1] - lo[a1])
            p[..., a2] = lo[a2] + q * (hi[a2] - lo[a2])
            p[..., axis] = hi[axis] if side else lo[axis]
            p = p.reshape(-1, 3)
            c = np.clip(p, ilo, ihi)
            d = p - c
            nrm = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
            p = c + r * nrm
            uv = np.stack([p[:, a1], p[:, a2]], 1) / tile
            meshes.append({"v": p, "f": grid_faces(n, n), "n": nrm, "uv": uv})
    return merge(*meshes)


def cylinder(p0, p1, r, seg=48, rings=4, caps=True, tile=1.0):
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    ax = p1 - p0
    L = np.linalg.norm(ax)
    w = ax / L
    u = np.cross(w, [0.0, 1.0, 0.0] if abs(w[1]) < 0.9 else [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(w, u)
    ang = np.linspace(0, 2 * np.pi, seg + 1)
    h = np.linspace(0, 1, rings + 1)
    A, H = np.meshgrid(ang, h, indexing="xy")
    rad = np.cos(A)[..., None] * u + np.sin(A)[..., None] * v
    pts = p0 + H[..., None] * ax + r * rad
    side = {"v": pts.reshape(-1, 3), "f": grid_faces(seg, rings), "n": rad.reshape(-1, 3),
            "uv": np.stack([A.ravel() * r / tile, H.ravel() * L / tile], 1)}
    parts = [side]
    if caps:
        for c, sgn in ((p0, -1.0), (p1, 1.0)):
            ring = c + r * (np.cos(ang[:-1])[:, None] * u + np.sin(ang[:-1])[:, None] * v)
            vv = np.concatenate([[c], ring])
            k = np.arange(seg)
            f = np.stack([np.zeros(seg, int), 1 + k, 1 + (k + 1) % seg], 1)
            if sgn < 0:
                f = f[:, [0, 2, 1]]
            parts.append({"v": vv, "f": f, "n": np.tile(sgn * w, (seg + 1, 1)),
                          "uv": (vv[:, [0, 2]] - c[[0, 2]]) / tile})
    return merge(*parts)


def sphere(c, r, seg=96):
    c = np.asarray(c, float)
    th = np.linspace(0, np.pi, seg // 2 + 1)
    ph = np.linspace(0, 2 * np.pi, seg + 1)
    P, T = np.meshgrid(ph, th, indexing="xy")
    nrm = np.stack([np.sin(T) * np.cos(P), np.cos(T), np.sin(T) * np.sin(P)], -1).reshape(-1, 3)
    return {"v": c + r * nrm, "f": grid_faces(seg, seg // 2)[:, [0, 2, 1]], "n": nrm,
            "uv": np.stack([P.ravel() / (2 * np.pi), 1 - T.ravel() / np.pi], 1)}


def quad(corner, eu, ev, uv_size=None):
    """A rectangle corner + s eu + t ev; UVs (s, t), or in metres / uv_size (a repeat)."""
    corner, eu, ev = (np.asarray(x, float) for x in (corner, eu, ev))
    v = np.array([corner, corner + eu, corner + ev, corner + eu + ev])
    nrm = np.cross(eu, ev)
    nrm /= np.linalg.norm(nrm)
    st = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], float)
    if uv_size is not None:
        st = st * [np.linalg.norm(eu) / uv_size, np.linalg.norm(ev) / uv_size]
    return {"v": v, "f": np.array([[0, 1, 3], [0, 3, 2]]), "n": np.tile(nrm, (4, 1)), "uv": st}


def on_wall(m, origin, ea, en):
    """A mesh built in wall coordinates (a along the wall, b up, d out of it) put on a wall."""
    ea, en = np.asarray(ea, float), np.asarray(en, float)
    R = np.stack([ea, [0.0, 1.0, 0.0], en], 1)  # columns: local x, y, z -> world
    out = dict(m)
    out["v"] = np.asarray(origin, float) + m["v"] @ R.T
    out["n"] = m["n"] @ R.T
    if np.linalg.det(R) < 0:
        out["f"] = m["f"][:, [0, 2, 1]]
    return out


# ---------------------------------------------------------------------------------------------
# Textures (linear reflectance arrays, row 0 at the top = v 1)


def wallpaper(contrast, base, ink, n=16):
    """A diamond lattice with a dot in each diamond: one n x n repeat. `contrast` None: printed
    ink on paper; a number c: the paper ±c (diamonds (1 + c) x, background (1 - c) x)."""
    y, x = np.mgrid[0:n, 0:n] + 0.5
    u, v = x / n - 0.5, y / n - 0.5
    diamond = (np.abs(u) + np.abs(v)) < 0.34
    ring = np.abs(np.abs(u) + np.abs(v) - 0.42) < 0.035
    dot = (u * u + v * v) < 0.06 ** 2
    base = np.asarray(base, float)
    if contrast is None:
        img = np.tile(base, (n, n, 1))
        img[diamond] = ink
        img[ring] = 0.5 * (base + np.asarray(ink))
        img[dot] = base
    else:
        img = np.tile(base * (1 - contrast), (n, n, 1))
        img[diamond] = base * (1 + contrast)
    return img


def wood(rng, w, h, planks, tone):
    """Planks along u (rows of the image), each with its own tone and grain."""
    img = np.zeros((h, w, 3))
    per = h // planks
    y, x = np.mgrid[0:h, 0:w]
    for p in range(planks):
        t = np.asarray(tone) * (0.75 + 0.5 * rng.random())
        rows = slice(p * per, (p + 1) * per)
        phase = rng.random() * 6.28
        grain = 0.85 + 0.15 * np.sin(x[rows] * (0.35 + 0.2 * rng.random()) + phase
                                     + 2.0 * np.sin(y[rows] * 0.9))
        img[rows] = t * grain[..., None]
        img[p * per] = t * 0.45  # the dark joint between planks
        cut = rng.integers(w // 4, w)
        img[rows, cut] = t * 0.5
    return img


def painting(kind, rng, w, h):
    y, x = np.mgrid[0:h, 0:w] + 0.5
    u, v = x / w, y / h
    img = np.zeros((h, w, 3))
    if kind == "landscape":
        sky = np.stack([0.25 + 0.3 * v, 0.4 + 0.3 * v, 0.75 - 0.2 * v], -1)
        img[:] = sky
        hills = 0.55 + 0.12 * np.sin(u * 9 + 1) + 0.05 * np.sin(u * 23)
        img[v > hills] = (0.12, 0.35, 0.08)
        img[v > 0.82] = (0.35, 0.25, 0.1)
        img[(u - 0.75) ** 2 + ((v - 0.22) * h / w) ** 2 < 0.07 ** 2] = (0.9, 0.75, 0.2)
    elif kind == "blocks":
        img[:] = (0.8, 0.78, 0.7)
        for _ in range(9):
            x0, y0 = rng.random(2) * 0.8
            cw, ch = 0.1 + 0.25 * rng.random(2)
            col = rng.choice([(0.7, 0.05, 0.04), (0.05, 0.1, 0.55), (0.8, 0.65, 0.05),
                              (0.02, 0.02, 0.02)])
            img[(u > x0) & (u < x0 + cw) & (v > y0) & (v < y0 + ch)] = col
        img[(np.abs(u - 0.5) < 0.01) | (np.abs(v - 0.6) < 0.015)] = 0.02
    else:  # stripes
        k = (np.floor(u * 12)).astype(int) % 4
        cols = np.array([(0.75, 0.2, 0.1), (0.9, 0.85, 0.7), (0.1, 0.3, 0.5), (0.9, 0.85, 0.7)])
        img[:] = cols[k] * (0.8 + 0.2 * v)[..., None]
    return img


def rug(w, h):
    y, x = np.mgrid[0:h, 0:w] + 0.5
    u, v = x / w - 0.5, y / h - 0.5
    img = np.tile(np.array([0.45, 0.08, 0.07]), (h, w, 1))
    border = (np.abs(u) > 0.42) | (np.abs(v) > 0.40)
    img[border] = (0.08, 0.1, 0.3)
    inner = ((np.abs(u) > 0.38) | (np.abs(v) > 0.35)) & ~border
    img[inner] = (0.7, 0.6, 0.35)
    med = (np.abs(u) * 1.2 + np.abs(v) * 1.6) < 0.22
    img[med] = (0.7, 0.6, 0.35)
    img[(np.abs(u) * 1.2 + np.abs(v) * 1.6) < 0.12] = (0.08, 0.1, 0.3)
    return img


# ---------------------------------------------------------------------------------------------
# Materials: the matfit material (TOML inline table), the truth in matfit's terms, the Mitsuba BSDF


def rgb(x):
    x = [float(x)] * 3 if np.isscalar(x) else [float(c) for c in x]
    return x


def fmt(x):
    return "[" + ", ".join(f"{c:.4g}" for c in rgb(x)) + "]"


def mrgb(name, x):
    return f'<rgb name="{name}" value="{", ".join(f"{c:.6g}" for c in rgb(x))}"/>'


def bitmap(name, path):
    return (f'<texture type="bitmap" name="{name}"><string name="filename" value="{path}"/>'
            '<string name="filter_type" value="bilinear"/>'
            '<string name="wrap_mode" value="repeat"/></texture>')


class Scene:
    def __init__(self, out, name):
        self.out = out
        self.name = name
        self.groups = {}  # name -> {"toml", "truth", "mitsuba"}
        self.objects = []  # (name, group, file or toml shape, emission)
        self.triangles = 0
        os.makedirs(os.path.join(out, "meshes"), exist_ok=True)
        os.makedirs(os.path.join(out, "textures"), exist_ok=True)
        self.textures = {}

    def texture(self, name, img):
        path = os.path.join(self.out, "textures", name + ".png")
        texels = write_png(path, img)
        self.textures[name] = texels
        return "textures/" + name + ".png", texels

    def group(self, name, toml, mitsuba, exact=True, **truth):
        truth.setdefault("rho_d", None)
        truth.setdefault("rho_s", None)
        truth.setdefault("alpha", None)
        truth.setdefault("texture", None)
        truth["exact_in_matfit"] = exact
        self.groups[name] = {"toml": toml, "mitsuba": mitsuba, "truth": truth}

    def diffuse(self, name, rho):
        self.group(name, f'{{ type = "diffuse", rho_d = {fmt(rho)} }}',
                   f'<bsdf type="diffuse">{mrgb("reflectance", rho)}</bsdf>',
                   model="diffuse", level=1, rho_d=rgb(rho))

    def plastic(self, name, rho, alpha):
        self.group(name, f'{{ type = "plastic", rho_d = {fmt(rho)}, rho_s = {F0:.5f}, '
                         f'alpha = {alpha} }}',
                   f'<bsdf type="roughplastic"><string name="distribution" value="ggx"/>'
                   f'<float name="alpha" value="{alpha}"/>{mrgb("diffuse_reflectance", rho)}'
                   '</bsdf>',
                   model="plastic", level=9, rho_d=rgb(rho), rho_s=rgb(F0), alpha=alpha)

    def metal(self, name, spec, alpha):
        self.group(name, f'{{ type = "microfacet", rho_d = 0.0, rho_s = {fmt(spec)}, '
                         f'alpha = {alpha} }}',
                   '<bsdf type="roughconductor"><string name="material" value="none"/>'
                   f'<string name="distribution" value="ggx"/><float name="alpha" value="{alpha}"/>'
                   f'{mrgb("specular_reflectance", spec)}</bsdf>',
                   model="microfacet", level=8, rho_d=rgb(0.0), rho_s=rgb(spec), alpha=alpha)

    def mirror(self, name, spec):
        self.group(name, f'{{ type = "mirror", rho_s = {fmt(spec)} }}',
                   '<bsdf type="conductor"><string name="material" value="none"/>'
                   f'{mrgb("specular_reflectance", spec)}</bsdf>',
                   model="mirror", level=3, rho_s=rgb(spec))

    def textured(self, name, tex, img):
        file, texels = self.texture(tex, img)
        self.group(name, f'{{ type = "textured", texture = "{file}" }}',
                   f'<bsdf type="diffuse">{bitmap("reflectance", "@DIR@/" + file)}</bsdf>',
                   model="textured", level=7, texture=file,
                   texture_mean=texels.reshape(-1, 3).mean(0).tolist())

    def textured_plastic(self, name, tex, img, alpha):
        """A textured diffuse base under a rough dielectric coat. matfit has no such model: its
        scene file gets a textured material varnished with a Ward lobe of about the coat's
        reflectance (an approximation; the truth is the Mitsuba BSDF)."""
        file, texels = self.texture(tex, img)
        self.group(name, f'{{ type = "textured", texture = "{file}", rho_s = {F0:.4f}, '
                         f'alpha = {alpha} }}',
                   f'<bsdf type="roughplastic"><string name="distribution" value="ggx"/>'
                   f'<float name="alpha" value="{alpha}"/>'
                   f'{bitmap("diffuse_reflectance", "@DIR@/" + file)}</bsdf>',
                   exact=False, model="textured_plastic", level=7, texture=file,
                   texture_mean=texels.reshape(-1, 3).mean(0).tolist(), rho_s=rgb(F0),
                   alpha=alpha, note="texture is the base under the coat; rho_s is the coat's "
                                     "normal-incidence reflectance (eta 1.49)")

    def mesh(self, name, group, m):
        assert group in self.groups, group
        file = f"meshes/{name}.ply"
        write_ply(os.path.join(self.out, file), m["v"], m["f"], m["n"], m["uv"])
        self.objects.append((name, group, f'shape = "mesh"\nfile = "{file}"', None))
        self.triangles += len(m["f"])

    def shape(self, name, group, toml, triangles, emission=None):
        self.objects.append((name, group, toml, emission))
        self.triangles += triangles


def camera_toml(cam):
    return (f"[camera]\nwidth = {cam['width']}\nheight = {cam['height']}\n"
            f"eye = {fmt(cam['eye'])}\ntarget = {fmt(cam['target'])}\nup = [0.0, 1.0, 0.0]\n"
            f"fov_y_deg = {cam['fov']}\n")


def write_scene(sc, header, render, cam, novel, extra_truth):
    objs = []
    for name, group, shape, emission in sc.objects:
        s = f'[[object]]\nname = "{name}"\ngroup = "{group}"\n{shape}\n'
        if emission is not None:
            s += f"emission = {fmt(emission)}\n"
        else:
            s += f"material = {sc.groups[group]['toml']}\n"
        objs.append(s)
    body = "\n".join(objs)
    for fname, c in (("scene.toml", cam), ("scene_novel.toml", novel)):
        with open(os.path.join(sc.out, fname), "w") as f:
            f.write(header + "\n" + render + "\n" + camera_toml(c) + "\n" + body)
    bsdfs = {g: d["mitsuba"] for g, d in sc.groups.items()}
    with open(os.path.join(sc.out, "mitsuba_bsdfs.json"), "w") as f:
        json.dump(bsdfs, f, indent=1)
    truth = {"scene": sc.name, "triangles": sc.triangles, "camera": cam, "novel_camera": novel,
             "groups": {}}
    truth.update(extra_truth)
    for g, d in sc.groups.items():
        t = dict(d["truth"])
        t["objects"] = [o[0] for o in sc.objects if o[1] == g]
        t["mitsuba"] = d["mitsuba"]
        truth["groups"][g] = t
    with open(os.path.join(sc.out, "truth.json"), "w") as f:
        json.dump(truth, f, indent=1)
    return truth


# ---------------------------------------------------------------------------------------------
# The interior


def build_interior(out, seed, contrast):
    rng = np.random.default_rng(seed)
    sc = Scene(out, "interior")
    W, H, D = 6.0, 3.0, 8.0  # x in [-3, 3], y in [0, 3], z in [-8, 0]
    x0, x1, zb = -W / 2, W / 2, -D

    # --- groups
    paper, ink = np.array([0.62, 0.58, 0.48]), np.array([0.12, 0.22, 0.38])
    sc.textured("wallpaper", "wallpaper", wallpaper(None, paper, ink))  # 16 texels per 0.4 m
    sc.textured("wallpaper_soft", "wallpaper_soft",
                wallpaper(contrast, np.array([0.55, 0.6, 0.52]), None))
    sc.textured_plastic("floor_wood", "floor_wood", wood(rng, 64, 64, 8, (0.42, 0.25, 0.12)), 0.15)
    sc.textured_plastic("stairs_wood", "stairs_wood", wood(rng, 32, 32, 4, (0.5, 0.32, 0.16)), 0.12)
    sc.plastic("paint_white", (0.8, 0.79, 0.76), 0.3)
    sc.diffuse("ceiling", (0.85, 0.85, 0.83))
    sc.diffuse("beams", (0.35, 0.24, 0.15))
    sc.diffuse("front_wall", (0.6, 0.55, 0.5))
    sc.metal("brass", (0.91, 0.72, 0.38), 0.18)
    sc.metal("gold", (1.0, 0.78, 0.34), 0.08)
    sc.mirror("mirror", (0.85, 0.85, 0.85))
    sc.plastic("frame_black", (0.03, 0.03, 0.03), 0.2)
    sc.diffuse("frame_wood", (0.4, 0.26, 0.14))
    sc.textured("painting_landscape", "painting_landscape", painting("landscape", rng, 40, 30))
    sc.textured("painting_blocks", "painting_blocks", painting("blocks", rng, 32, 40))
    sc.textured("painting_stripes", "painting_stripes", painting("stripes", rng, 36, 24))
    sc.diffuse("sofa_fabric", (0.2, 0.3, 0.5))
    sc.diffuse("cushion", (0.6, 0.12, 0.1))
    sc.plastic("table_top", (0.3, 0.17, 0.08), 0.1)
    sc.metal("steel", (0.6, 0.6, 0.62), 0.3)
    sc.textured("rug", "rug", rug(48, 32))
    sc.plastic("ball_red", (0.7, 0.05, 0.04), 0.05)
    sc.plastic("door", (0.15, 0.35, 0.25), 0.25)
    sc.diffuse("lamp_shade", (0.8, 0.75, 0.6))
    sc.diffuse("pot", (0.55, 0.25, 0.15))
    sc.plastic("vase", (0.05, 0.15, 0.5), 0.08)
    sc.diffuse("rail_wood", (0.3, 0.18, 0.09))

    # --- the room's shell (walls as meshes so that the wallpaper repeats in metres)
    tile = 0.4
    sc.mesh("floor", "floor_wood", quad([x0, 0, 0], [0, 0, -D], [W, 0, 0], uv_size=1.6))
    sc.mesh("back_wall_left", "wallpaper", quad([x0, 0, zb], [2.55, 0, 0], [0, H, 0], tile))
    sc.mesh("back_wall_right", "wallpaper",
            quad([0.65, 0, zb], [x1 - 0.65, 0, 0], [0, H, 0], tile))
    sc.mesh("back_wall_over_door", "wallpaper",
            quad([-0.45, 2.2, zb], [1.1, 0, 0], [0, H - 2.2, 0], tile))
    sc.mesh("right_wall", "wallpaper", quad([x1, 0, zb], [0, 0, D], [0, H, 0], tile))
    sc.mesh("left_wall", "wallpaper_soft", quad([x0, 0, 0], [0, 0, -D], [0, H, 0], tile))
    sc.mesh("front_wall", "front_wall", quad([x1, 0, 0], [-W, 0, 0], [0, H, 0], tile))
    sc.mesh("ceiling", "ceiling", quad([x0, H, 0], [W, 0, 0], [0, 0, -D], 1.0))
    for i, z in enumerate(np.linspace(-1.0, -7.0, 4)):
        sc.mesh(f"beam{i}", "beams", rounded_box([x0, H - 0.22, z - 0.1], [x1, H, z + 0.1],
                                                 0.02, 12))
    # Two ceiling lights, emitting downwards (out of view).
    for i, z in enumerate((-2.6, -5.6)):
        sc.shape(f"light{i}", "light",
                 f'shape = "quad"\ncorner = [-0.6, {H - 0.01}, {z + 0.4}]\n'
                 f"edge_u = [0.0, 0.0, -0.8]\nedge_v = [1.2, 0.0, 0.0]", 2, emission=9.0)

    # --- skirting boards (paint) along the three seen walls
    sc.mesh("skirting_back", "paint_white", rounded_box([x0, 0, zb], [x1, 0.12, zb + 0.02],
                                                        0.006, 24))
    sc.mesh("skirting_left", "paint_white", rounded_box([x0, 0, zb], [x0 + 0.02, 0.12, 0],
                                                        0.006, 24))
    sc.mesh("skirting_right", "paint_white", rounded_box([x1 - 0.02, 0, zb], [x1, 0.12, 0],
                                                         0.006, 24))

    # --- the door in the back wall, its painted frame and a brass handle
    sc.mesh("door_leaf", "door", rounded_box([-0.4, 0.0, zb - 0.02], [0.6, 2.15, zb + 0.03],
                                             0.01, 24))
    for i, (lo, hi) in enumerate((([-0.5, 0, zb], [-0.4, 2.25, zb + 0.05]),
                                  ([0.6, 0, zb], [0.7, 2.25, zb + 0.05]),
                                  ([-0.5, 2.15, zb], [0.7, 2.25, zb + 0.05]))):
        sc.mesh(f"door_frame{i}", "paint_white", rounded_box(lo, hi, 0.01, 16))
    sc.mesh("door_handle", "brass", merge(
        cylinder([0.48, 1.0, zb + 0.03], [0.48, 1.0, zb + 0.09], 0.012, 32, 2),
        cylinder([0.48, 1.0, zb + 0.09], [0.36, 1.0, zb + 0.09], 0.01, 32, 4),
        sphere([0.48, 1.0, zb + 0.09], 0.016, 32)))

    # --- the staircase along the right wall: 12 bevelled treads (wood) on painted risers
    n_steps, rise, run = 12, 0.18, 0.3
    for k in range(n_steps):
        z_front = -3.2 - k * run
        y = (k + 1) * rise
        sc.mesh(f"tread{k:02d}", "stairs_wood",
                rounded_box([1.75, y - 0.04, z_front - run], [x1, y, z_front + 0.03], 0.012, 20,
                            tile=0.8))
        sc.mesh(f"riser{k:02d}", "paint_white",
                rounded_box([1.78, y - rise, z_front - 0.02], [x1, y - 0.04, z_front], 0.005, 12))
        # a brass baluster on every tread's inner end
        sc.mesh(f"baluster{k:02d}", "brass",
                cylinder([1.85, y, z_front - run / 2], [1.85, y + 0.9, z_front - run / 2], 0.018,
                         32, 12))
    z_a, z_b = -3.2 - run / 2, -3.2 - (n_steps - 0.5) * run
    sc.mesh("handrail", "rail_wood",
            cylinder([1.85, rise + 0.92, z_a], [1.85, n_steps * rise + 0.92, z_b], 0.035, 48, 16))
    sc.mesh("stair_side", "paint_white",
            merge(*[rounded_box([1.72, 0, -3.2 - k * run - run], [1.78, (k + 1) * rise,
                                                                  -3.2 - k * run], 0.004, 8)
                    for k in range(n_steps)]))

    # --- pictures: thin frames (4 bevelled bars each) around textured paintings
    def picture(tag, wall, a0, b0, w, h, frame_group, paint_group, bar=0.035):
        origin, ea, en = wall
        sc.mesh(f"{tag}_canvas", paint_group,
                on_wall(quad([a0, b0, 0.012], [w, 0, 0], [0, h, 0]), origin, ea, en))
        bars = [([a0 - bar, b0 - bar, 0], [a0 + w + bar, b0, 0.03]),
                ([a0 - bar, b0 + h, 0], [a0 + w + bar, b0 + h + bar, 0.03]),
                ([a0 - bar, b0, 0], [a0, b0 + h, 0.03]),
                ([a0 + w, b0, 0], [a0 + w + bar, b0 + h, 0.03])]
        sc.mesh(f"{tag}_frame", frame_group,
                on_wall(merge(*[rounded_box(lo, hi, 0.008, 16) for lo, hi in bars]),
                        origin, ea, en))

    back = ([0, 0, zb], [1, 0, 0], [0, 0, 1])
    left = ([x0, 0, 0], [0, 0, -1], [1, 0, 0])  # a runs along -z, the normal is +x
    picture("landscape", back, -2.5, 1.25, 1.0, 0.75, "gold", "painting_landscape")
    picture("blocks", left, 4.4, 1.2, 0.6, 0.75, "frame_black", "painting_blocks")
    picture("stripes", left, 6.2, 1.35, 0.9, 0.6, "frame_wood", "painting_stripes")
    # The mirror on the back wall, right of the door, in a black frame.
    sc.mesh("mirror_glass", "mirror", on_wall(quad([1.0, 1.0, 0.015], [0.6, 0, 0], [0, 1.0, 0]),
                                              *back))
    picture_bars = [([0.96, 0.96, 0], [1.64, 1.0, 0.03]), ([0.96, 2.0, 0], [1.64, 2.04, 0.03]),
                    ([0.96, 1.0, 0], [1.0, 2.0, 0.03]), ([1.6, 1.0, 0], [1.64, 2.0, 0.03])]
    sc.mesh("mirror_frame", "frame_black",
            on_wall(merge(*[rounded_box(lo, hi, 0.008, 16) for lo, hi in picture_bars]), *back))

    # --- the sofa against the left wall, its cushions
    sx0, sz0, sz1 = x0 + 0.05, -6.4, -4.2
    sc.mesh("sofa_base", "sofa_fabric", rounded_box([sx0, 0.08, sz0], [sx0 + 0.9, 0.4, sz1], 0.05, 28))
    sc.mesh("sofa_back", "sofa_fabric", rounded_box([sx0, 0.4, sz0], [sx0 + 0.22, 0.95, sz1], 0.06, 28))
    sc.mesh("sofa_arm0", "sofa_fabric", rounded_box([sx0, 0.08, sz0 - 0.2], [sx0 + 0.9, 0.65, sz0],
                                                   0.06, 24))
    sc.mesh("sofa_arm1", "sofa_fabric", rounded_box([sx0, 0.08, sz1], [sx0 + 0.9, 0.65, sz1 + 0.2],
                                                   0.06, 24))
    for i, (za, zc) in enumerate(((sz0, -5.3), (-5.3, sz1))):
        sc.mesh(f"seat{i}", "sofa_fabric", rounded_box([sx0 + 0.22, 0.4, za + 0.01],
                                                       [sx0 + 0.88, 0.52, zc - 0.01], 0.05, 28))
    for i, zc in enumerate((-6.0, -4.7)):
        sc.mesh(f"cushion{i}", "cushion", rounded_box([sx0 + 0.2, 0.5, zc - 0.22],
                                                      [sx0 + 0.36, 0.9, zc + 0.22], 0.06, 28))
    for i, z in enumerate((sz0 - 0.15, sz1 + 0.15)):  # little steel feet
        for j, x in enumerate((sx0 + 0.08, sx0 + 0.8)):
            sc.mesh(f"sofa_foot{i}{j}", "steel", cylinder([x, 0, z], [x, 0.08, z], 0.025, 32, 2))

    # --- the rug, the coffee table, the balls, the vase
    sc.mesh("rug", "rug", quad([-1.6, 0.006, -4.3], [0, 0, -2.4], [2.6, 0, 0]))
    sc.mesh("table_top", "table_top", rounded_box([-1.0, 0.42, -5.9], [0.4, 0.47, -4.9], 0.012, 32))
    for i, (x, z) in enumerate(((-0.93, -5.83), (0.33, -5.83), (-0.93, -4.97), (0.33, -4.97))):
        sc.mesh(f"table_leg{i}", "steel", cylinder([x, 0.006, z], [x, 0.42, z], 0.02, 32, 6))
    sc.mesh("ball_red", "ball_red", sphere([-0.6, 0.59, -5.4], 0.12, 128))
    sc.mesh("ball_gold", "gold", sphere([0.05, 0.55, -5.55], 0.08, 96))
    sc.mesh("vase", "vase", merge(cylinder([-0.15, 0.47, -5.2], [-0.15, 0.7, -5.2], 0.06, 64, 8),
                                  sphere([-0.15, 0.7, -5.2], 0.06, 64)))

    # --- the floor lamp (brass pole, diffuse shade) and a plant pot by the stairs
    sc.mesh("lamp_pole", "brass", merge(cylinder([-2.3, 0.0, -7.3], [-2.3, 0.03, -7.3], 0.16, 64, 2),
                                        cylinder([-2.3, 0.03, -7.3], [-2.3, 1.5, -7.3], 0.015, 32, 20)))
    sc.mesh("lamp_shade", "lamp_shade", cylinder([-2.3, 1.45, -7.3], [-2.3, 1.75, -7.3], 0.2, 96, 8,
                                                 caps=False))
    sc.mesh("pot", "pot", cylinder([1.3, 0.0, -3.6], [1.3, 0.4, -3.6], 0.17, 96, 16))
    sc.mesh("pot_rim", "pot", cylinder([1.3, 0.38, -3.6], [1.3, 0.44, -3.6], 0.19, 96, 4))

    # --- cameras: the photo sees neither the ceiling, nor the beams, nor the front wall.
    cam = {"width": 480, "height": 270, "eye": [0.4, 1.55, -0.6], "target": [-0.3, -0.69, -7.5],
           "fov": 50.0}
    novel = {"width": 480, "height": 270, "eye": [-1.8, 1.3, -1.4], "target": [1.2, 0.6, -6.8],
             "fov": 48.0}
    header = ("# The decisions issue's textured interior, written by scenes/interior/generate.py "
              f"(seed {seed},\n# wallpaper contrast {contrast}). Truth: truth.json; the Mitsuba "
              "BSDFs that are the truth: mitsuba_bsdfs.json.\n# floor_wood and stairs_wood are "
              "a textured base under a rough dielectric coat (Mitsuba roughplastic):\n# matfit has "
              "no such model, so this file carries a Ward-varnished texture instead.\n")
    render = "[render]\nspp = 128\nmax_depth = 6\nseed = 1\n"
    return write_scene(sc, header, render, cam, novel, {"wallpaper_contrast": contrast,
                                                        "seed": seed})


# ---------------------------------------------------------------------------------------------
# The measured-materials room: materials that are not matfit's models


def build_measured(out, seed):
    sc = Scene(out, "measured")
    # matfit-exact groups: the box's shell.
    sc.diffuse("white", (0.73, 0.73, 0.73))
    sc.diffuse("red", (0.63, 0.06, 0.05))
    sc.diffuse("floor", (0.6, 0.58, 0.55))

    def other(name, toml, mitsuba, **truth):
        sc.group(name, toml, mitsuba, exact=False, **truth)

    # principled with sheen, clearcoat and specular tint.
    base = (0.15, 0.45, 0.25)
    other("principled", f'{{ type = "plastic", rho_d = {fmt(base)}, rho_s = {F0:.5f}, '
                        'alpha = 0.16 }',
          '<bsdf type="principled">' + mrgb("base_color", base) +
          '<float name="roughness" value="0.4"/><float name="metallic" value="0.0"/>'
          '<float name="specular" value="0.6"/><float name="spec_tint" value="0.7"/>'
          '<float name="sheen" value="0.8"/><float name="sheen_tint" value="0.5"/>'
          '<float name="clearcoat" value="0.7"/><float name="clearcoat_gloss" value="0.8"/>'
          '</bsdf>',
          model="principled", level=None, rho_d=None, rho_s=None, alpha=None,
          albedo_from="mitsuba", note="principled (sheen, clearcoat, spec_tint): no matfit "
          "parameter has a truth; the measured hemispherical albedo is given")
    # blendbsdf: a rough conductor over a diffuse base.
    other("blend", '{ type = "microfacet", rho_d = [0.35, 0.1, 0.05], rho_s = 0.4, alpha = 0.2 }',
          '<bsdf type="blendbsdf"><float name="weight" value="0.4"/>'
          '<bsdf type="diffuse">' + mrgb("reflectance", (0.58, 0.17, 0.08)) + '</bsdf>'
          '<bsdf type="roughconductor"><string name="material" value="Al"/>'
          '<string name="distribution" value="beckmann"/><float name="alpha" value="0.2"/></bsdf>'
          '</bsdf>',
          model="blendbsdf", level=None, rho_d=rgb((0.6 * 0.58, 0.6 * 0.17, 0.6 * 0.08)),
          rho_s=None, alpha=0.2, albedo_from="mitsuba",
          note="0.6 x diffuse (0.58, 0.17, 0.08) + 0.4 x Beckmann Al conductor (spectral "
               "Fresnel): rho_d = 0.6 x base is exact, alpha 0.2 is Beckmann's; rho_s has no "
               "truth (Al's Fresnel is not a constant)")
    # spectral-IOR conductors (Fresnel of Cu, Au; matfit's microfacet has no Fresnel).
    other("copper", '{ type = "microfacet", rho_d = 0.0, rho_s = [0.95, 0.64, 0.54], alpha = 0.1 }',
          '<bsdf type="roughconductor"><string name="material" value="Cu"/>'
          '<string name="distribution" value="ggx"/><float name="alpha" value="0.1"/></bsdf>',
          model="roughconductor Cu", level=None, rho_d=rgb(0.0), rho_s=None, alpha=0.1,
          albedo_from="mitsuba", note="rho_d 0 and alpha exact; rho_s has no truth "
                                      "(Cu's Fresnel varies with the angle)")
    other("gold_ball", '{ type = "microfacet", rho_d = 0.0, rho_s = [1.0, 0.78, 0.34], alpha = 0.06 }',
          '<bsdf type="roughconductor"><string name="material" value="Au"/>'
          '<string name="distribution" value="ggx"/><float name="alpha" value="0.06"/></bsdf>',
          model="roughconductor Au", level=None, rho_d=rgb(0.0), rho_s=None, alpha=0.06,
          albedo_from="mitsuba", note="rho_d 0 and alpha exact; rho_s has no truth")
    # smooth plastic, nonlinear (the base's internal scattering changes its colour).
    nl = (0.7, 0.55, 0.1)
    other("plastic_nl", f'{{ type = "plastic", rho_d = {fmt(nl)}, rho_s = {F0:.5f}, alpha = 0.01 }}',
          '<bsdf type="plastic">' + mrgb("diffuse_reflectance", nl) +
          '<boolean name="nonlinear" value="true"/></bsdf>',
          model="plastic nonlinear", level=None, rho_d=None, rho_s=rgb(F0), alpha=0.0,
          albedo_from="mitsuba", note="smooth coat (alpha 0, a delta lobe) of eta 1.49: rho_s "
          "exact; the base's effective albedo is nonlinear in diffuse_reflectance, no rho_d truth")
    # the back wall: principled metallic with anisotropy.
    other("back_wall", '{ type = "microfacet", rho_d = [0.5, 0.5, 0.55], rho_s = 0.2, alpha = 0.3 }',
          '<bsdf type="principled">' + mrgb("base_color", (0.55, 0.55, 0.6)) +
          '<float name="roughness" value="0.5"/><float name="metallic" value="0.3"/>'
          '<float name="anisotropic" value="0.5"/><float name="specular" value="0.5"/></bsdf>',
          model="principled metallic anisotropic", level=None, albedo_from="mitsuba",
          note="no matfit parameter has a truth")

    S = 2.0  # the box: x in [-1, 1], y in [0, 2], z in [-2, 0]; the camera looks along -z
    sc.mesh("floor", "floor", quad([-1, 0, 0], [0, 0, -S], [S, 0, 0]))
    sc.mesh("ceiling", "white", quad([-1, S, 0], [S, 0, 0], [0, 0, -S]))
    sc.mesh("back_wall", "back_wall", quad([-1, 0, -S], [S, 0, 0], [0, S, 0]))
    sc.mesh("left_wall", "red", quad([-1, 0, 0], [0, S, 0], [0, 0, -S]))
    sc.mesh("right_wall", "white", quad([1, 0, -S], [0, S, 0], [0, 0, S]))
    sc.shape("light", "light", 'shape = "quad"\ncorner = [-0.3, 1.99, -0.7]\n'
             "edge_u = [0.0, 0.0, -0.6]\nedge_v = [0.6, 0.0, 0.0]", 2, emission=17.0)
    sc.mesh("tall_block", "principled", rounded_box([-0.7, 0, -1.6], [-0.2, 1.2, -1.1], 0.03, 32))
    sc.mesh("short_block", "blend", rounded_box([0.15, 0, -1.3], [0.7, 0.55, -0.75], 0.03, 32))
    sc.mesh("copper_cyl", "copper", cylinder([0.45, 0.55, -1.0], [0.45, 0.85, -1.0], 0.12, 128, 16))
    sc.mesh("gold_ball", "gold_ball", sphere([-0.45, 0.22, -0.6], 0.22, 160))
    sc.mesh("plastic_ball", "plastic_nl", sphere([0.35, 0.2, -0.35], 0.2, 160))
    cam = {"width": 256, "height": 256, "eye": [0.0, 1.0, 2.4], "target": [0.0, 0.8, -1.0],
           "fov": 40.0}
    novel = {"width": 256, "height": 256, "eye": [0.7, 1.5, 1.2], "target": [-0.2, 0.5, -1.2],
             "fov": 45.0}
    header = ("# The decisions issue's measured-materials room, written by "
              "scenes/interior/generate.py.\n# Its blocks, balls and back wall are Mitsuba "
              "BSDFs that are NOT matfit's models (mitsuba_bsdfs.json);\n# this file carries "
              "the nearest matfit material as a placeholder. RGL measured BRDFs were not\n# "
              "reachable from this machine; truth.json says which parameters have a truth.\n")
    render = "[render]\nspp = 128\nmax_depth = 6\nseed = 1\n"
    return write_scene(sc, header, render, cam, novel, {"seed": seed})


# ---------------------------------------------------------------------------------------------
# Mitsuba: matfit's export of the scene with every group's BSDF replaced by the true one


def mitsuba_albedos(scene_dir, n=1 << 15):
    """For every uniform group (no texture): the directional-hemispherical albedo of its true
    Mitsuba BSDF (the mean of its sampling weight, n samples, one-sided, the incident
    direction's azimuth cycling through 8 as matfit's `albedo` averages them) at incidences 0
    and 60 degrees, written into truth.json as `albedo_0deg`, `albedo_60deg`: the truth a
    recovery's albedo (results.json) is compared with when its model is not the truth's.
    Needs Mitsuba (bench/setup_mitsuba.sh); skipped without it."""
    try:
        import mitsuba as mi
    except ImportError:
        return False
    mi.set_variant("scalar_rgb")
    path = os.path.join(scene_dir, "truth.json")
    truth = json.load(open(path))
    rng = np.random.default_rng(0)
    u = rng.random((n, 3))
    for g, t in truth["groups"].items():
        if t.get("texture") or not t.get("mitsuba"):
            continue
        bsdf = mi.load_string(t["mitsuba"].replace("@DIR@", os.path.abspath(scene_dir))
                              .replace("<bsdf ", '<bsdf version="3.0.0" ', 1))
        ctx = mi.BSDFContext()
        for deg in (0, 60):
            th = np.radians(deg)
            acc = np.zeros(3)
            for k in range(n):
                phi = 2 * np.pi * ((k % 8) + 0.5) / 8
                si = mi.SurfaceInteraction3f()
                si.n = mi.Vector3f(0, 0, 1)
                si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
                si.wi = mi.Vector3f(np.sin(th) * np.cos(phi), np.sin(th) * np.sin(phi),
                                    np.cos(th))
                si.uv = mi.Point2f(0.5, 0.5)
                _, w = bsdf.sample(ctx, si, float(u[k, 0]), mi.Point2f(u[k, 1], u[k, 2]))
                acc += np.array([w[0], w[1], w[2]])
            t[f"albedo_{deg}deg"] = (acc / n).round(4).tolist()
    with open(path, "w") as f:
        json.dump(truth, f, indent=1)
    return True


def find_matfit():
    for d in (os.environ.get("CARGO_TARGET_DIR"), os.path.join(ROOT, "target")):
        if d and os.access(os.path.join(d, "release", "matfit"), os.X_OK):
            return os.path.join(d, "release", "matfit")
    return shutil.which("matfit")


def assemble_mitsuba(scene_dir, matfit, scene_file="scene.toml", name="scene.xml"):
    """`matfit export mitsuba` of scene_dir/scene_file into scene_dir/mitsuba/, every group's
    BSDF (defined once, id = the group's name, wrapped in `twosided`) replaced by the one in
    mitsuba_bsdfs.json. Returns the XML's path."""
    out = os.path.join(scene_dir, "mitsuba", os.path.splitext(name)[0])
    subprocess.run([matfit, "export", "mitsuba", os.path.join(scene_dir, scene_file), "-o", out,
                    "--force"], check=True, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL)
    xml = open(os.path.join(out, "scene.xml")).read()
    bsdfs = json.load(open(os.path.join(scene_dir, "mitsuba_bsdfs.json")))
    absdir = os.path.abspath(scene_dir)
    done = dict.fromkeys(bsdfs, 0)

    def true_bsdf(g, indent):
        return indent + bsdfs[g].replace("@DIR@", absdir)

    # Groups whose objects share one BSDF: defined once, id = the group's name.
    for g in bsdfs:
        pat = re.compile(r'(<bsdf type="twosided" id="%s">\n).*?(\n    </bsdf>)' % re.escape(g),
                         re.S)
        xml, n = pat.subn(lambda m: m.group(1) + true_bsdf(g, "        ") + m.group(2), xml)
        done[g] += n

    # Objects with their own BSDF (a texture is loaded per object, so a textured group's
    # objects each carry one): the inline `twosided` at the shape's indentation.
    def per_object(m):
        head, g, body = m.group(1), m.group(2), m.group(3)
        if g not in bsdfs:
            return m.group(0)
        body, n = re.subn(r'(\n        <bsdf type="twosided">\n).*?(\n        </bsdf>)',
                          lambda k: k.group(1) + true_bsdf(g, "            ") + k.group(2),
                          body, count=1, flags=re.S)
        done[g] += n
        return head + body

    xml = re.sub(r"(<!-- object '[^']*', group '([^']*)' -->)(.*?</shape>)", per_object, xml,
                 flags=re.S)
    missing = [g for g, n in done.items() if n == 0]
    if missing:
        raise SystemExit(f"groups {missing}: no BSDF of theirs found in the export")
    path = os.path.join(scene_dir, "mitsuba", name)
    # The meshes are relative to the export's folder.
    xml = xml.replace('value="meshes/', f'value="{os.path.basename(out)}/meshes/')
    with open(path, "w") as f:
        f.write(xml)
    return path


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scene", nargs="?", default="interior", choices=["interior", "measured"])
    ap.add_argument("-o", "--output", help="folder (default /tmp/matfit-scenes/SCENE)")
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--wallpaper-contrast", type=float, default=0.10,
                    help="the low-contrast wallpaper's diamonds: ±C around its paper (0.10)")
    ap.add_argument("--matfit", help="matfit binary for the Mitsuba XML (default: found in "
                                     "$CARGO_TARGET_DIR or target/; none: skip the XML)")
    ap.add_argument("--albedos-only", metavar="DIR",
                    help="only (re)compute the true albedos in DIR's truth.json (a folder this "
                         "script wrote before) and stop")
    a = ap.parse_args()
    if a.albedos_only:
        if not mitsuba_albedos(a.albedos_only):
            sys.exit("no Mitsuba: run bench/setup_mitsuba.sh and source bench/mitsuba_env.sh")
        return
    out = a.output or os.path.join("/tmp/matfit-scenes", a.scene)
    if os.path.isdir(out):
        for sub in ("meshes", "textures", "mitsuba"):
            shutil.rmtree(os.path.join(out, sub), ignore_errors=True)
    os.makedirs(out, exist_ok=True)
    if a.scene == "interior":
        truth = build_interior(out, a.seed, a.wallpaper_contrast)
    else:
        truth = build_measured(out, a.seed)
    if not mitsuba_albedos(out):
        print("  no Mitsuba: the groups' true albedos are not in truth.json",
              file=sys.stderr)
    print(f"{a.scene}: {truth['triangles']} triangles, {len(truth['groups'])} groups -> {out}")
    matfit = a.matfit or find_matfit()
    if matfit:
        for f, n in (("scene.toml", "scene.xml"), ("scene_novel.toml", "novel.xml")):
            print("  ", assemble_mitsuba(out, matfit, f, n))
    else:
        print("  no matfit binary: mitsuba/*.xml not written (pass --matfit)", file=sys.stderr)


if __name__ == "__main__":
    main()
