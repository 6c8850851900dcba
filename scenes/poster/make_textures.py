#!/usr/bin/env python3
"""Writes the poster scene's ground-truth reflectance textures (8-bit sRGB PNG, decoded to
linear reflectance by matfit). Procedural and deterministic, so they carry no licence of their
own: the same files as in the repository come out of

    python3 scenes/poster/make_textures.py

Pure Python (zlib, struct): nothing to install. Each texture has fine detail (one-texel lines,
one-texel checks), saturated colour and dark regions, as issue 21 asks. The poster's and the
books' texels are sized to the photo: at the scene's 480×360 a texel spans about two pixels, the
finest detail one photo resolves (a one-texel line, a period of four pixels). Finer detail
than that no single photo holds; at half the resolution (the CI test) a texel is one pixel.
"""
import math
import os
import struct
import zlib

HERE = os.path.dirname(os.path.abspath(__file__))


def srgb8(x):
    x = min(max(x, 0.0), 1.0)
    v = 12.92 * x if x <= 0.0031308 else 1.055 * x ** (1 / 2.4) - 0.055
    return int(round(v * 255))


def write_png(name, w, h, pixel):
    """pixel(x, y) -> linear (r, g, b); row 0 at the top."""
    raw = bytearray()
    for y in range(h):
        raw.append(0)
        for x in range(w):
            raw.extend(srgb8(c) for c in pixel(x, y))

    def chunk(tag, data):
        c = struct.pack(">I", len(data)) + tag + data
        return c + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    png = b"\x89PNG\r\n\x1a\n"
    png += chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
    png += chunk(b"IDAT", zlib.compress(bytes(raw), 9))
    png += chunk(b"IEND", b"")
    with open(os.path.join(HERE, name), "wb") as f:
        f.write(png)


def hash01(x, y, k=0):
    """A deterministic value noise in [0, 1)."""
    n = (x * 374761393 + y * 668265263 + k * 2147483647) & 0xFFFFFFFF
    n = ((n ^ (n >> 13)) * 1274126177) & 0xFFFFFFFF
    return ((n ^ (n >> 16)) & 0xFFFF) / 65536.0


def poster(x, y):
    w, h = 64, 48
    u, v = (x + 0.5) / w, (y + 0.5) / h
    c = (0.72 - 0.2 * v, 0.66 - 0.15 * v, 0.50 - 0.1 * v)  # cream, darkening downwards
    if (u - 0.3) ** 2 + ((v - 0.38) * 0.75) ** 2 < 0.2 ** 2:  # a saturated red sun
        c = (0.75, 0.06, 0.04)
    if 0.55 < u < 0.92 and 0.12 < v < 0.55:  # a blue block with a one-texel yellow frame
        c = (0.04, 0.10, 0.55)
        if u < 0.57 or u > 0.90 or v < 0.14 or v > 0.53:
            c = (0.85, 0.70, 0.05)
    if 0.62 < u < 0.85 and 0.22 < v < 0.45 and (x + y) % 2 == 0:  # one-texel checks
        c = (0.80, 0.80, 0.75)
    if v > 0.68:  # a black band with white "text": one-texel strokes
        c = (0.02, 0.02, 0.025)
        row = y - int(0.72 * h)
        if 0 <= row < 10 and row % 5 in (1, 3) and 3 < x < 61 and hash01(x // 2, y // 5) > 0.35:
            c = (0.82, 0.82, 0.80)
    if 0.06 < u < 0.5 and 0.60 < v < 0.66:  # a green stripe
        c = (0.05, 0.45, 0.12)
    return c


BOOKS = [
    (0.45, 0.04, 0.04),  # oxblood
    (0.04, 0.07, 0.30),  # navy
    (0.05, 0.28, 0.10),  # forest green
    (0.70, 0.50, 0.06),  # mustard
    (0.03, 0.03, 0.03),  # black
    (0.04, 0.35, 0.38),  # teal
]


def book(k):
    base = BOOKS[k]
    gold = (0.80, 0.60, 0.15)
    w, h = 10, 24

    def px(x, y):
        if y in (1, 22) or (k % 2 == 0 and y in (3, 20)):  # one-texel gold bands
            return gold
        if 6 <= y < 16 and 1 <= x < w - 1:  # title label with one-texel lines of "text"
            label = tuple(min(1.0, 0.2 + 1.6 * c) for c in base) if k != 4 else (0.75, 0.72, 0.6)
            if (y - 6) % 3 == 1 and hash01(x, y, k) > 0.3:
                return (0.02, 0.02, 0.02)
            return label
        g = 0.9 + 0.1 * hash01(x, y, 7 + k)  # cloth weave
        return tuple(c * g for c in base)

    return px


def desk(x, y):
    # Wood grain: rings bent by a slow wobble, with fine dark pores.
    t = x + 7.0 * math.sin(y / 11.0) + 3.0 * math.sin(y / 4.3 + 1.0)
    ring = 0.5 + 0.5 * math.sin(t / 2.7)
    r = (0.50 - 0.18 * ring, 0.30 - 0.11 * ring, 0.14 - 0.06 * ring)
    if hash01(x, y // 3, 3) > 0.975:
        r = tuple(c * 0.5 for c in r)
    return r


if __name__ == "__main__":
    write_png("poster.png", 64, 48, poster)
    for k in range(len(BOOKS)):
        write_png(f"book{k}.png", 10, 24, book(k))
    write_png("desk.png", 128, 80, desk)
