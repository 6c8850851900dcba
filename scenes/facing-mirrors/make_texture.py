#!/usr/bin/env python3
"""Writes the facing-mirrors scene's book cover and painting, their ground-truth reflectance
textures (8-bit sRGB PNG, decoded to linear reflectance by matfit). Procedural and deterministic, so it carries no
licence of its own: the same files as in the repository come out of

    python3 scenes/facing-mirrors/make_texture.py

Pure Python (zlib, struct): nothing to install. Detail a few texels wide (the photo resolves
it in the mirror too), saturated colour and a dark band.
"""
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


def cover(x, y):
    """A 48 × 64 book cover: a teal field, a dark band, a cream title block with lines of type,
    an orange disc."""
    u, v = (x + 0.5) / 48, (y + 0.5) / 64
    c = (0.05, 0.35, 0.38)  # teal cloth
    if 0.78 < v < 0.86:
        c = (0.03, 0.03, 0.04)  # dark band
    if 0.12 < u < 0.88 and 0.1 < v < 0.42:  # title block
        c = (0.75, 0.70, 0.55)
        if 0.15 < v < 0.38 and 0.2 < u < 0.8 and y % 8 < 4:
            c = (0.08, 0.05, 0.05)  # lines of type, four texels (about 3 px) thick
    if (u - 0.5) ** 2 + (v - 0.62) ** 2 < 0.12 ** 2:
        c = (0.85, 0.35, 0.05)  # an orange disc
    return c


def painting(x, y):
    """A 64 × 48 painting: a sky going from blue to pale, a red sun, green hills with a dark
    outline, a cream frame."""
    u, v = (x + 0.5) / 64, (y + 0.5) / 48
    if u < 0.05 or u > 0.95 or v < 0.066 or v > 0.934:
        return (0.70, 0.62, 0.45)  # frame
    c = (0.10 + 0.5 * v, 0.25 + 0.4 * v, 0.65)  # sky
    if (u - 0.68) ** 2 + (v - 0.3) ** 2 < 0.11 ** 2:
        c = (0.80, 0.08, 0.04)  # sun
    hill = 0.62 + 0.08 * ((u * 7.0) % 2.0 - 1.0) ** 2
    if v > hill:
        c = (0.10, 0.45, 0.12) if v > hill + 0.04 else (0.03, 0.05, 0.03)
    return c


if __name__ == "__main__":
    write_png("book.png", 48, 64, cover)
    write_png("painting.png", 64, 48, painting)
