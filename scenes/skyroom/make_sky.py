#!/usr/bin/env python3
"""Writes sky.pfm, the environment map of scenes/skyroom: a procedural sky (no licence of its
own), equirectangular 96 x 48, linear radiance. Rows run from the zenith (top) to the nadir;
column u looks along (sin 2πu, 0, −cos 2πu) (Mitsuba's envmap convention, scene/environment.rs).
A blue sky brightening to the horizon, a dim brown ground, and a sun 40° up, 3° wide.

    python3 scenes/skyroom/make_sky.py     # standard library only
"""
import math
import os
import struct

W, H = 96, 48
SUN_ELEV, SUN_AZ, SUN_RADIUS = math.radians(40), math.radians(60), math.radians(3)
sun = (math.cos(SUN_ELEV) * math.sin(SUN_AZ), math.sin(SUN_ELEV), -math.cos(SUN_ELEV) * math.cos(SUN_AZ))

rows = []
for j in range(H):
    theta = math.pi * j / (H - 1)
    row = []
    for i in range(W):
        phi = 2 * math.pi * i / W
        d = (math.sin(theta) * math.sin(phi), math.cos(theta), -math.sin(theta) * math.cos(phi))
        if d[1] >= 0:
            t = 1 - d[1]
            c = [0.25 + 0.5 * t, 0.4 + 0.45 * t, 0.9 + 0.2 * t]
        else:
            c = [0.12, 0.1, 0.08]
        cosang = sum(a * b for a, b in zip(d, sun))
        ang = math.acos(max(-1.0, min(1.0, cosang)))
        s = 400.0 * math.exp(-(ang / SUN_RADIUS) ** 2)
        row.append([c[0] + s, c[1] + 0.95 * s, c[2] + 0.85 * s])
    rows.append(row)

out = os.path.join(os.path.dirname(os.path.abspath(__file__)), "sky.pfm")
with open(out, "wb") as f:
    f.write(b"PF\n%d %d\n-1.0\n" % (W, H))
    for row in reversed(rows):  # PFM stores the bottom row first
        for c in row:
            f.write(struct.pack("<3f", *c))
print("wrote", out)
