"""Writes an office at the size of a real room: scene.toml and its meshes (binary PLY).

Issue 24's scaling scene. A furnished room 8 × 3 × 7 m, lit by two ceiling area lights: walls,
floor (anisotropic Ward, as figure6's), ceiling, a mirror on the back wall, a detailed sculpture
(a displaced sphere, glossy Ward) and furniture — desks with glossy Ward tops, chairs, bookcases,
cabinets, paintings, a rug and rows of books, one group each — every box tessellated.

Three sizes can be set independently, so that the same script makes the full scene and the
reduced variants of bench/scale.py:
  --width/--height  the camera's pixels (default 1920 × 1080)
  --groups          how many groups (10 to 46; the first 9 are the room, lights, mirror and
                    sculpture, then furniture in a fixed order; default 46)
  --triangles       about how many triangles in all (default 1.2M): half go to the sculpture,
                    half to the furniture's tessellated boxes (at least 12 per box)
  --diffuse         every surface diffuse: Ward surfaces keep their ρd, the mirror becomes
                    grey 0.5 (the forward comparison with Mitsuba in bench/compare.py)

Run: python3 scenes/office-large/make_scene.py [--out DIR] (default: this folder). Writes
DIR/scene.toml and DIR/meshes/*.ply; they are generated, not committed (see .gitignore).
Pure Python 3 (no numpy): about 2 s for the full scene.
"""

import argparse
import math
import os
import struct
import sys
from array import array

ROOM_W, ROOM_H, ROOM_D = 8.0, 3.0, 7.0  # x ∈ [-4, 4], y ∈ [0, 3], z ∈ [-7, 0]
CORE_GROUPS = 9  # floor, ceiling, 3 wall groups, 2 lights, mirror, sculpture
DIFFUSE = False  # --diffuse: ward() and the mirror give diffuse materials


class Mesh:
    """Triangles accumulated for one PLY file."""

    def __init__(self):
        self.v = array("f")
        self.f = array("i")

    def vertex(self, p):
        self.v.extend(p)
        return len(self.v) // 3 - 1

    def tri(self, a, b, c):
        self.f.extend((a, b, c))

    def grid(self, corner, eu, ev, n):
        """An n × n grid of quads over the parallelogram corner + s eu + t ev (2 n² triangles),
        facing eu × ev."""
        base = len(self.v) // 3
        for j in range(n + 1):
            t = j / n
            for i in range(n + 1):
                s = i / n
                self.v.extend(corner[k] + s * eu[k] + t * ev[k] for k in range(3))
        for j in range(n):
            for i in range(n):
                a = base + j * (n + 1) + i
                self.f.extend((a, a + 1, a + n + 2, a, a + n + 2, a + n + 1))

    def box(self, lo, hi, n):
        """An axis-aligned box, each face an n × n grid (12 n² triangles), faces outwards."""
        (x0, y0, z0), (x1, y1, z1) = lo, hi
        dx, dy, dz = x1 - x0, y1 - y0, z1 - z0
        self.grid((x0, y0, z0), (0, dy, 0), (dx, 0, 0), n)  # -z
        self.grid((x0, y0, z1), (dx, 0, 0), (0, dy, 0), n)  # +z
        self.grid((x0, y0, z0), (0, 0, dz), (0, dy, 0), n)  # -x
        self.grid((x1, y0, z0), (0, dy, 0), (0, 0, dz), n)  # +x
        self.grid((x0, y0, z0), (dx, 0, 0), (0, 0, dz), n)  # -y
        self.grid((x0, y1, z0), (0, 0, dz), (dx, 0, 0), n)  # +y

    def triangles(self):
        return len(self.f) // 3

    def write_ply(self, path):
        nv, nf = len(self.v) // 3, len(self.f) // 3
        header = (
            "ply\nformat binary_little_endian 1.0\n"
            f"element vertex {nv}\nproperty float x\nproperty float y\nproperty float z\n"
            f"element face {nf}\nproperty list uchar int vertex_indices\nend_header\n"
        )
        with open(path, "wb") as out:
            out.write(header.encode())
            assert sys.byteorder == "little"  # array's bytes are native
            out.write(self.v.tobytes())
            # Each face: a count byte then three little-endian ints.
            rec = struct.Struct("<B3i")
            f = self.f
            out.write(b"".join(rec.pack(3, f[i], f[i + 1], f[i + 2]) for i in range(0, len(f), 3)))


def sculpture(center, radius, n):
    """A displaced UV sphere of 2 n (n - 1) + … ≈ 4 n² triangles (n rings, 2 n segments): the
    detailed mesh, standing in for a scanned object."""
    m = Mesh()
    cx, cy, cz = center
    rings, segs = n, 2 * n
    sin, cos = math.sin, math.cos
    for j in range(rings + 1):
        th = math.pi * j / rings
        for i in range(segs):
            ph = 2 * math.pi * i / segs
            bumps = 0.08 * sin(6 * th) * cos(5 * ph) + 0.02 * sin(31 * th) * sin(27 * ph)
            r = radius * (1 + bumps)
            m.v.extend((cx + r * sin(th) * cos(ph), cy + r * cos(th), cz + r * sin(th) * sin(ph)))
    for j in range(rings):
        for i in range(segs):
            a, b = j * segs + i, j * segs + (i + 1) % segs
            c, d = a + segs, b + segs
            if j > 0:
                m.tri(a, b, d)
            if j < rings - 1:
                m.tri(a, d, c)
    return m


def rgb(c):
    """An RGB triple as TOML: [r, g, b]."""
    return f"[{c[0]}, {c[1]}, {c[2]}]"


def diffuse(c):
    """A diffuse material of reflectance `c`: an RGB tuple, or a grey given as its text."""
    rho = rgb(c) if isinstance(c, tuple) else c
    return f'{{ type = "diffuse", rho_d = {rho} }}'


def ward(c, rho_s, lobe):
    """A Ward material: `lobe` is its roughness keys, "alpha = …" or "alpha_x = …, …"."""
    if DIFFUSE:
        return diffuse(c)
    rho = rgb(c) if isinstance(c, tuple) else c
    return f'{{ type = "ward", rho_d = {rho}, rho_s = {rho_s}, {lobe} }}'


def legs(x, z, dx, dz, half, height):
    """Four legs of square section 2·half at (x ± dx, z ± dz), from the floor to `height`."""
    return [((x + sx * dx - half, 0, z + sz * dz - half),
             (x + sx * dx + half, height, z + sz * dz + half))
            for sx in (-1, 1) for sz in (-1, 1)]


def furniture():
    """The furniture in the order groups are added: (name, boxes, material, tangent). Boxes are
    (lo, hi) corners; materials are TOML inline tables."""
    items = []

    def desk(k, x, z):
        top = ((x - 0.7, 0.72, z - 0.4), (x + 0.7, 0.76, z + 0.4))
        mat = ward((0.32, 0.2, 0.1), 0.08, "alpha_x = 0.08, alpha_y = 0.2, theta_deg = 0.0")
        boxes = [top] + legs(x, z, 0.65, 0.35, 0.03, 0.72)
        items.append((f"desk_{k}", boxes, mat, (1.0, 0.0, 0.0)))

    def chair(k, x, z, c):
        seat = ((x - 0.23, 0.44, z - 0.23), (x + 0.23, 0.48, z + 0.23))
        back = ((x - 0.23, 0.48, z + 0.19), (x + 0.23, 0.95, z + 0.23))
        boxes = [seat, back] + legs(x, z, 0.2, 0.2, 0.02, 0.44)
        items.append((f"chair_{k}", boxes, ward(c, 0.05, "alpha = 0.15"), None))

    def bookcase(k, x0):
        # Against the back wall, 1.6 m wide, 2.0 m high, 0.35 m deep; sides, back, 5 boards.
        z1 = -ROOM_D + 0.01
        boxes = [((x0, 0, z1), (x0 + 0.03, 2.0, z1 + 0.35)),
                 ((x0 + 1.57, 0, z1), (x0 + 1.6, 2.0, z1 + 0.35)),
                 ((x0, 0, z1), (x0 + 1.6, 2.0, z1 + 0.02))]
        boxes += [((x0 + 0.03, y, z1), (x0 + 1.57, y + 0.025, z1 + 0.35))
                  for y in (0.0, 0.48, 0.96, 1.44, 1.975)]
        items.append((f"bookcase_{k}", boxes, diffuse((0.55, 0.45, 0.35)), None))

    def cabinet(k, x, z, c):
        box = ((x - 0.4, 0, z - 0.25), (x + 0.4, 0.9, z + 0.25))
        items.append((f"cabinet_{k}", [box], diffuse(c), None))

    def painting(k, wall_x, z, c):
        s = 1 if wall_x < 0 else -1
        lo = (wall_x if s > 0 else wall_x - 0.03, 1.2, z - 0.5)
        hi = (wall_x + 0.03 if s > 0 else wall_x, 2.0, z + 0.5)
        items.append((f"painting_{k}", [(lo, hi)], ward(c, 0.04, "alpha = 0.08"), None))

    desk(1, 1.8, -3.0)
    chair(1, 1.8, -2.35, (0.1, 0.15, 0.5))
    bookcase(1, -2.6)
    cabinet(1, 3.4, -5.5, (0.7, 0.7, 0.68))
    painting(1, 4.0, -4.5, (0.6, 0.25, 0.2))
    desk(2, 1.8, -5.0)
    chair(2, 1.8, -4.35, (0.5, 0.1, 0.1))
    bookcase(2, -0.8)
    rug = ((-1.5, 0.0, -4.2), (0.5, 0.012, -2.2))
    items.append(("rug", [rug], diffuse((0.45, 0.12, 0.1)), None))
    painting(2, -4.0, -6.35, (0.2, 0.4, 0.55))
    desk(3, -1.2, -5.6)
    chair(3, -1.2, -4.95, (0.15, 0.4, 0.15))
    cabinet(2, 3.4, -6.4, (0.3, 0.3, 0.32))
    # Rows of books, one group per row: 2 bookcases × 4 shelves × 3 rows of 0.45 m.
    palette = [(0.6, 0.1, 0.1), (0.1, 0.3, 0.6), (0.1, 0.45, 0.2), (0.7, 0.6, 0.2),
               (0.4, 0.2, 0.5), (0.8, 0.8, 0.75), (0.15, 0.15, 0.15), (0.6, 0.35, 0.15)]
    k = 0
    for case_x in (-2.6, -0.8):
        for shelf_y in (0.025, 0.505, 0.985, 1.465):
            for row in range(3):
                k += 1
                x0 = case_x + 0.06 + row * 0.5
                books = []
                for b in range(9):
                    h = 0.24 + 0.1 * ((b * 7 + k) % 5) / 4
                    bx = x0 + b * 0.05
                    lo, hi = (bx, shelf_y, -ROOM_D + 0.05), (bx + 0.045, shelf_y + h, -ROOM_D + 0.3)
                    books.append((lo, hi))
                items.append((f"books_{k}", books, diffuse(palette[k % 8]), None))
    return items


def fmt(v):
    return "[" + ", ".join(f"{x:g}" for x in v) + "]"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.dirname(os.path.abspath(__file__)))
    ap.add_argument("--width", type=int, default=1920)
    ap.add_argument("--height", type=int, default=1080)
    ap.add_argument("--groups", type=int, default=46)
    ap.add_argument("--triangles", type=float, default=1.2e6)
    ap.add_argument("--spp", type=int, default=64, help="the scene's [render] spp")
    ap.add_argument("--diffuse", action="store_true", help="every surface diffuse")
    a = ap.parse_args()
    global DIFFUSE
    DIFFUSE = a.diffuse
    items = furniture()
    if not CORE_GROUPS + 1 <= a.groups <= CORE_GROUPS + len(items):
        ap.error(f"--groups must be in {CORE_GROUPS + 1}..{CORE_GROUPS + len(items)}")
    items = items[: a.groups - CORE_GROUPS]
    os.makedirs(os.path.join(a.out, "meshes"), exist_ok=True)

    # Half the triangles to the sculpture, half spread evenly over the furniture's boxes.
    budget = max(a.triangles, 1000)
    nboxes = sum(len(b) for _, b, _, _ in items)
    n_box = max(1, round(math.sqrt(budget / 2 / (12 * nboxes))))
    n_sculpt = max(8, round(math.sqrt(budget / 2 / 4)))

    head = [
        "# office-large (issue 24), generated by make_scene.py: "
        f"--width {a.width} --height {a.height} --groups {a.groups} --triangles {a.triangles:g}"
        + (" --diffuse" if a.diffuse else ""),
        "[render]", f"spp = {a.spp}", "max_depth = 8", "seed = 1", 'ward_variant = "ward1992"', "",
        "[camera]", f"width = {a.width}", f"height = {a.height}",
        "eye = [0.0, 1.6, -0.3]", "target = [0.3, 1.05, -4.5]", "up = [0.0, 1.0, 0.0]",
        "fov_y_deg = 52.0", "",
    ]
    objs = []
    total = 0

    def quad(name, group, corner, eu, ev, mat=None, emission=None, tangent=None):
        nonlocal total
        total += 2
        o = ["[[object]]", f'name = "{name}"', f'group = "{group}"', 'shape = "quad"',
             f"corner = {fmt(corner)}", f"edge_u = {fmt(eu)}", f"edge_v = {fmt(ev)}"]
        if tangent:
            o.append(f"tangent = {fmt(tangent)}")
        if mat:
            o.append(f"material = {mat}")
        if emission:
            o.append(f"emission = {emission}")
        objs.append("\n".join(o) + "\n")

    def mesh(name, m, mat, tangent=None):
        nonlocal total
        total += m.triangles()
        m.write_ply(os.path.join(a.out, "meshes", f"{name}.ply"))
        o = ["[[object]]", f'name = "{name}"', f'group = "{name}"', 'shape = "mesh"',
             f'file = "meshes/{name}.ply"']
        if tangent:
            o.append(f"tangent = {fmt(tangent)}")
        o.append(f"material = {mat}")
        objs.append("\n".join(o) + "\n")

    x0, x1, d, h = -ROOM_W / 2, ROOM_W / 2, -ROOM_D, ROOM_H
    floor = ward("0.12", 0.6, "alpha_x = 0.07, alpha_y = 0.11, theta_deg = 0.0")
    quad("floor", "floor", (x0, 0, 0), (ROOM_W, 0, 0), (0, 0, d), floor, tangent=(1, 0, 0))
    quad("ceiling", "ceiling", (x0, h, 0), (0, 0, d), (ROOM_W, 0, 0), diffuse("0.8"))
    wall = diffuse((0.7, 0.68, 0.6))
    quad("back_wall", "back_wall", (x0, 0, d), (ROOM_W, 0, 0), (0, h, 0), wall)
    quad("front_wall", "back_wall", (x0, 0, 0), (0, h, 0), (ROOM_W, 0, 0), wall)
    quad("left_wall", "left_wall", (x0, 0, 0), (0, 0, d), (0, h, 0), diffuse((0.45, 0.6, 0.7)))
    quad("right_wall", "right_wall", (x1, 0, 0), (0, h, 0), (0, 0, d), diffuse((0.75, 0.65, 0.45)))
    quad("light_1", "light_1", (-1.6, h - 0.01, -2.6), (1.2, 0, 0), (0, 0, 0.6), emission=25.0)
    quad("light_2", "light_2", (0.8, h - 0.01, -5.2), (1.2, 0, 0), (0, 0, 0.6), emission=25.0)
    mirror = diffuse("0.5") if DIFFUSE else '{ type = "mirror", rho_s = 0.9 }'
    quad("mirror", "mirror", (1.0, 1.1, d + 0.01), (1.6, 0, 0), (0, 1.2, 0), mirror)
    statue = sculpture((-1.9, 0.5, -3.4), 0.45, n_sculpt)
    mesh("sculpture", statue, ward((0.5, 0.45, 0.35), 0.15, "alpha = 0.12"))
    for name, boxes, mat, tangent in items:
        m = Mesh()
        for lo, hi in boxes:
            m.box(lo, hi, n_box)
        mesh(name, m, mat, tangent)

    with open(os.path.join(a.out, "scene.toml"), "w") as out:
        out.write("\n".join(head) + "\n" + "\n".join(objs))
    print(f"{a.out}/scene.toml: {a.width}x{a.height}, {a.groups} groups, {total} triangles")


if __name__ == "__main__":
    main()
