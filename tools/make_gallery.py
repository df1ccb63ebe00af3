#!/usr/bin/env python3
"""Write a gallery of ordinary Mitsuba 3 scenes and their assets.

Usage::

    python tools/make_gallery.py [--out scenes_xml/gallery]

Writes ``<name>.xml`` for every scene of :data:`SCENES` into the output folder,
and the assets they use under ``meshes/``, ``textures/`` and ``envmaps/``
next to them.  Every asset is made here with numpy, no downloads: triangle
meshes as OBJ (text) and PLY (binary little-endian and ASCII), 8-bit sRGB
PNG textures and a half-float lat-long OpenEXR environment map.  The PNG,
EXR and PLY encoders are the small ones below, and every float is rounded
before it is written, so a rerun writes the same bytes.

Conventions of every scene:

* ``<scene version="3.0.0">``, Y up, the camera's up is +Y;
* ``<default>`` parameters ``res`` (film width and height in pixels; in
  ``crop_rgba`` the crop window's), ``spp`` (the sampler's ``sample_count``)
  and ``max_depth`` (the ``path`` integrator's), so that
  ``mi.load_file(path, res="16", spp="4")`` gives a small, fast version;
* asset paths are relative to the scene file (Mitsuba resolves them
  against the scene file's folder);
* every shape has an ``id``; the scene's header comment lists what it uses.
"""

from __future__ import annotations

import argparse
import struct
import zlib
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_OUT = ROOT / "scenes_xml" / "gallery"


# ----------------------------------------------------------------------------- encoders

def _q(a, digits=5):
    """Round to ``digits`` decimals (and turn -0 into 0) before writing floats."""
    return np.round(np.asarray(a, dtype=np.float64), digits) + 0.0


def png_bytes(rgb) -> bytes:
    """An 8-bit RGB PNG of ``rgb`` (H x W x 3 floats in [0, 1], already sRGB)."""
    rgb = np.asarray(rgb, dtype=np.float64)
    h, w, _ = rgb.shape
    px = np.clip(np.round(_q(rgb) * 255.0), 0, 255).astype(np.uint8)
    raw = b"".join(b"\x00" + px[r].tobytes() for r in range(h))  # filter 0 per row

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))

    ihdr = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)  # 8 bit, RGB, no interlace
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr)
            + chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))


def exr_bytes(rgb) -> bytes:
    """An uncompressed scanline OpenEXR file of ``rgb`` (H x W x 3, linear) as half floats."""
    rgb = np.asarray(rgb, dtype=np.float64)
    h, w, _ = rgb.shape

    def attr(name: str, kind: str, value: bytes) -> bytes:
        return name.encode() + b"\0" + kind.encode() + b"\0" + struct.pack("<i", len(value)) + value

    chlist = b"".join(c.encode() + b"\0" + struct.pack("<iB3xii", 1, 0, 1, 1)  # HALF
                      for c in "BGR") + b"\0"
    box = struct.pack("<iiii", 0, 0, w - 1, h - 1)
    header = (b"\x76\x2f\x31\x01" + struct.pack("<i", 2)
              + attr("channels", "chlist", chlist)
              + attr("compression", "compression", b"\0")
              + attr("dataWindow", "box2i", box)
              + attr("displayWindow", "box2i", box)
              + attr("lineOrder", "lineOrder", b"\0")
              + attr("pixelAspectRatio", "float", struct.pack("<f", 1.0))
              + attr("screenWindowCenter", "v2f", struct.pack("<ff", 0.0, 0.0))
              + attr("screenWindowWidth", "float", struct.pack("<f", 1.0))
              + b"\0")
    half = _q(rgb, 4).astype("<f2")
    line_size = w * 3 * 2
    first = len(header) + 8 * h
    offsets = struct.pack(f"<{h}Q", *[first + y * (8 + line_size) for y in range(h)])
    lines = b"".join(struct.pack("<ii", y, line_size)
                     + b"".join(half[y, :, c].tobytes() for c in (2, 1, 0))  # B, G, R
                     for y in range(h))
    return header + offsets + lines


def obj_text(v, f, n=None, uv=None, comment="") -> str:
    """Wavefront OBJ text: positions, optional texture coordinates and normals, triangles.

    ``uv`` are OpenGL-style (v up); Mitsuba's ``obj`` flips them by default
    (``flip_tex_coords``), which maps them the usual way onto bitmaps.
    """
    out = [f"# {comment}\n"] if comment else []
    out += [f"v {x:.5f} {y:.5f} {z:.5f}\n" for x, y, z in _q(v)]
    if uv is not None:
        out += [f"vt {a:.5f} {b:.5f}\n" for a, b in _q(uv)]
    if n is not None:
        out += [f"vn {x:.5f} {y:.5f} {z:.5f}\n" for x, y, z in _q(n)]
    for tri in np.asarray(f) + 1:
        if uv is not None and n is not None:
            out.append("f " + " ".join(f"{i}/{i}/{i}" for i in tri) + "\n")
        elif n is not None:
            out.append("f " + " ".join(f"{i}//{i}" for i in tri) + "\n")
        elif uv is not None:
            out.append("f " + " ".join(f"{i}/{i}" for i in tri) + "\n")
        else:
            out.append("f " + " ".join(str(i) for i in tri) + "\n")
    return "".join(out)


def ply_bytes(v, f, n=None, binary=True, comment="") -> bytes:
    """A PLY mesh (binary little-endian or ASCII): float x y z [nx ny nz], uchar/int face lists."""
    v = _q(v).astype(np.float32)
    f = np.asarray(f, dtype=np.int32)
    props = ["x", "y", "z"]
    cols = [v]
    if n is not None:
        props += ["nx", "ny", "nz"]
        cols.append(_q(n).astype(np.float32))
    head = ["ply", "format " + ("binary_little_endian" if binary else "ascii") + " 1.0"]
    if comment:
        head.append("comment " + comment)
    head.append(f"element vertex {len(v)}")
    head += [f"property float {p}" for p in props]
    head += [f"element face {len(f)}", "property list uchar int vertex_indices", "end_header"]
    header = ("\n".join(head) + "\n").encode("ascii")
    verts = np.concatenate(cols, axis=1)
    if binary:
        vdata = verts.astype("<f4").tobytes()
        faces = np.zeros(len(f), dtype=[("k", "u1"), ("i", "<i4", (3,))])
        faces["k"] = 3
        faces["i"] = f
        return header + vdata + faces.tobytes()
    lines = [" ".join(f"{x:.5f}" for x in row) for row in verts.astype(np.float64)]
    lines += ["3 " + " ".join(str(i) for i in tri) for tri in f]
    return header + ("\n".join(lines) + "\n").encode("ascii")


# ----------------------------------------------------------------------------- meshes

def vertex_normals(v, f):
    """Area-weighted vertex normals of a triangle mesh."""
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    n = np.zeros_like(v)
    for k in range(3):
        np.add.at(n, f[:, k], fn)
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def cube_mesh():
    """Unit cube [-1, 1]^3: 24 vertices (flat normals, one [0, 1]^2 uv square per face), 12 triangles."""
    v, n, uv, f = [], [], [], []
    for axis in range(3):
        for sign in (1.0, -1.0):
            normal = np.zeros(3)
            normal[axis] = sign
            a = np.zeros(3)
            a[(axis + 1) % 3] = 1.0
            b = np.cross(normal, a)
            base = len(v)
            for s, t in ((0, 0), (1, 0), (1, 1), (0, 1)):
                v.append(normal + (2 * s - 1) * a + (2 * t - 1) * b)
                n.append(normal)
                uv.append((s, t))
            f += [(base, base + 1, base + 2), (base, base + 2, base + 3)]
    return np.array(v), np.array(f), np.array(n), np.array(uv, dtype=float)


def torus_mesh(major=1.0, minor=0.35, nu=48, nv=24):
    """Torus around the Y axis, with uv and smooth normals; (nu + 1) (nv + 1) vertices (seams duplicated)."""
    u = np.linspace(0.0, 2 * np.pi, nu + 1)
    w = np.linspace(0.0, 2 * np.pi, nv + 1)
    U, W = np.meshgrid(u, w, indexing="ij")
    cx, cz = np.cos(U), np.sin(U)
    n = np.stack([cx * np.cos(W), np.sin(W), cz * np.cos(W)], axis=-1)
    v = np.stack([cx * major, np.zeros_like(U), cz * major], axis=-1) + minor * n
    uv = np.stack([U / (2 * np.pi), W / (2 * np.pi)], axis=-1)
    f = _grid_faces(nu, nv)
    return v.reshape(-1, 3), f, n.reshape(-1, 3), uv.reshape(-1, 2)


def _grid_faces(nu, nv, flip=False):
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    a = i * (nv + 1) + j
    b = (i + 1) * (nv + 1) + j
    t1 = np.stack([a, a + 1, b + 1], axis=-1).reshape(-1, 3)
    t2 = np.stack([a, b + 1, b], axis=-1).reshape(-1, 3)
    f = np.concatenate([t1, t2])
    return f[:, ::-1].copy() if flip else f


def tube_mesh(radius=1.0, height=2.0, n=40):
    """Open cylinder (no caps) around Y, y in [0, height]; seen from inside too (use ``twosided``)."""
    u = np.linspace(0.0, 2 * np.pi, n + 1)
    y = np.array([0.0, height])
    U, Y = np.meshgrid(u, y, indexing="ij")
    v = np.stack([radius * np.cos(U), Y, radius * np.sin(U)], axis=-1).reshape(-1, 3)
    nrm = np.stack([np.cos(U), 0 * U, np.sin(U)], axis=-1).reshape(-1, 3)
    uv = np.stack([U / (2 * np.pi), Y / height], axis=-1).reshape(-1, 2)
    return v, _grid_faces(n, 1, flip=True), nrm, uv


def pedestal_mesh(radius=1.0, height=0.3, n=32):
    """Closed cylinder (flat caps) around Y, y in [0, height], flat-shaded by Mitsuba (no normals)."""
    ang = 2 * np.pi * np.arange(n) / n
    ring = np.stack([radius * np.cos(ang), np.zeros(n), radius * np.sin(ang)], axis=-1)
    bottom, top = ring, ring + [0.0, height, 0.0]
    v = np.concatenate([bottom, top, [[0.0, 0.0, 0.0], [0.0, height, 0.0]]])
    cb, ct = 2 * n, 2 * n + 1
    f = []
    for k in range(n):
        k1 = (k + 1) % n
        f += [(k, n + k1, k1), (k, n + k, n + k1)]      # side, outward
        f += [(cb, k, k1), (ct, n + k1, n + k)]          # bottom (down), top (up)
    return v, np.array(f)


def icosphere(level):
    """Unit icosphere: 12 vertices and 20 triangles, each triangle split in four ``level`` times."""
    t = (1.0 + 5 ** 0.5) / 2.0
    v = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t),
         (0, -1, -t), (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    v = [np.array(p, dtype=float) / np.linalg.norm(p) for p in v]
    f = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
         (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
         (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    for _ in range(level):
        cache: dict = {}

        def mid(a, b):
            key = (min(a, b), max(a, b))
            if key not in cache:
                p = v[a] + v[b]
                v.append(p / np.linalg.norm(p))
                cache[key] = len(v) - 1
            return cache[key]

        nf = []
        for a, b, c in f:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            nf += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        f = nf
    return np.array(v), np.array(f)


def blob_mesh():
    """A bunny-like blob: a displaced icosphere (body, head, two ears, tail), flat bottom at y = 0."""
    d, f = icosphere(4)

    def bump(direction, width):
        e = np.asarray(direction, dtype=float)
        e = e / np.linalg.norm(e)
        return np.exp(-(1.0 - d @ e) / width)

    r = (1.0 + 0.45 * bump((0.75, 0.55, 0.0), 0.05)
         + 0.95 * bump((0.35, 1.0, 0.22), 0.008) + 0.95 * bump((0.35, 1.0, -0.22), 0.008)
         + 0.18 * bump((-1.0, 0.2, 0.0), 0.01))
    v = d * r[:, None] * np.array([1.0, 0.8, 0.75])
    v[:, 1] = np.maximum(v[:, 1], -0.55) + 0.55
    return v, f, vertex_normals(v, f)


# ----------------------------------------------------------------------------- textures

def _hash(ix, iy, seed):
    """Integer hash of a lattice point, in [0, 1)."""
    h = (np.asarray(ix, dtype=np.int64) * 374761393 + np.asarray(iy, dtype=np.int64) * 668265263
         + seed * 2246822519) & 0xFFFFFFFF
    h = ((h ^ (h >> 13)) * 1274126177) & 0xFFFFFFFF
    h = h ^ (h >> 16)
    return h.astype(np.float64) / 2.0 ** 32


def value_noise(x, y, seed):
    """Smooth value noise on the integer lattice (periodic only where the caller makes it so)."""
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = x - x0, y - y0
    sx, sy = fx * fx * (3 - 2 * fx), fy * fy * (3 - 2 * fy)
    h00, h10 = _hash(x0, y0, seed), _hash(x0 + 1, y0, seed)
    h01, h11 = _hash(x0, y0 + 1, seed), _hash(x0 + 1, y0 + 1, seed)
    return (h00 * (1 - sx) + h10 * sx) * (1 - sy) + (h01 * (1 - sx) + h11 * sx) * sy


def _uv(size):
    c = (np.arange(size) + 0.5) / size
    return np.meshgrid(c, c, indexing="xy")  # u along columns, v along rows (row 0 on top)


def checker_texture(size=256, cells=8):
    """High-contrast checkerboard: near-black and near-white squares."""
    u, v = _uv(size)
    odd = (np.floor(u * cells) + np.floor(v * cells)) % 2 == 1
    return np.where(odd[..., None], [0.04, 0.04, 0.045], [0.95, 0.95, 0.93])


def wood_texture(size=256, planks=8):
    """Wooden floor planks along u: per-plank tone, grain, darker seams."""
    u, v = _uv(size)
    k = np.floor(v * planks)
    offset = _hash(k, 0, 7)
    grain = value_noise(u * 6 + 31 * offset, v * planks * 1.5, 3)
    stripes = 0.5 + 0.5 * np.sin(2 * np.pi * (u * 10 + 2.5 * grain + 3 * offset))
    tone = 0.75 + 0.25 * _hash(k, 1, 11)
    base = np.array([0.62, 0.42, 0.24]) * tone[..., None]
    col = base * (0.82 + 0.18 * stripes[..., None])
    seam_v = np.abs(v * planks - np.round(v * planks)) * size / planks < 0.9
    pos = (u + offset) * 2.0
    seam_u = np.abs(pos - np.round(pos)) * size / 2.0 < 0.7
    return np.where((seam_v | seam_u)[..., None], col * 0.45, col)


def uvgrid_texture(size=128, cells=8):
    """Coloured uv grid: one hue per cell, white lines."""
    u, v = _uv(size)
    cu, cv = np.floor(u * cells), np.floor(v * cells)
    hue = (cu + cv * cells) / (cells * cells)
    col = 0.55 + 0.4 * np.cos(2 * np.pi * (hue[..., None] + np.array([0.0, 1 / 3, 2 / 3])))
    col *= np.where(((cu + cv) % 2 == 0)[..., None], 1.0, 0.8)
    line = ((np.abs(u * cells - np.round(u * cells)) * size / cells < 0.8)
            | (np.abs(v * cells - np.round(v * cells)) * size / cells < 0.8))
    return np.where(line[..., None], 0.97, col)


def crate_texture(size=128):
    """A wooden crate's face: frame, diagonal brace, slats."""
    u, v = _uv(size)
    grain = value_noise(u * 3, v * 24, 5)
    col = np.array([0.70, 0.52, 0.30]) * (0.8 + 0.2 * grain[..., None])
    frame = (u < 0.12) | (u > 0.88) | (v < 0.12) | (v > 0.88)
    brace = np.abs(u - v) < 0.07
    slat = np.abs(v * 4 - np.round(v * 4)) < 0.03
    col = np.where(slat[..., None], col * 0.5, col)
    col = np.where((frame | brace)[..., None], np.array([0.50, 0.34, 0.18]) * (0.85 + 0.15 * grain[..., None]), col)
    edge = ((np.abs(u - 0.12) < 0.01) | (np.abs(u - 0.88) < 0.01) | (np.abs(v - 0.12) < 0.01)
            | (np.abs(v - 0.88) < 0.01))
    return np.where(edge[..., None], col * 0.4, col)


SUN_DIR = np.array([-0.45, 0.62, 0.64])


def sky_envmap(width=128, height=64):
    """Lat-long sky (linear RGB): blue gradient, a bright sun, a dim brown ground below the horizon.

    Mitsuba's ``envmap`` maps image row 0 to +Y (up); column u to the
    direction (sin 2 pi u sin theta, cos theta, -cos 2 pi u sin theta).
    """
    u = (np.arange(width) + 0.5) / width
    v = (np.arange(height) + 0.5) / height
    U, V = np.meshgrid(u, v, indexing="xy")
    theta, phi = V * np.pi, U * 2 * np.pi
    d = np.stack([np.sin(phi) * np.sin(theta), np.cos(theta), -np.cos(phi) * np.sin(theta)], axis=-1)
    elev = d[..., 1]
    t = np.clip(elev, 0.0, 1.0) ** 0.6
    sky = (1 - t)[..., None] * np.array([0.95, 0.95, 1.0]) + t[..., None] * np.array([0.25, 0.45, 0.95])
    cloud = value_noise(U * 16, V * 10, 17)
    sky = sky * (0.85 + 0.3 * cloud[..., None])
    ground = np.array([0.22, 0.18, 0.14]) * (0.8 + 0.4 * value_noise(U * 24, V * 12, 19))[..., None]
    col = np.where((elev > 0)[..., None], sky, ground)
    sun = SUN_DIR / np.linalg.norm(SUN_DIR)
    cosang = np.clip(d @ sun, -1.0, 1.0)
    glow = 200.0 * np.exp(-(1.0 - cosang) / 0.0015) + 1.5 * np.exp(-(1.0 - cosang) / 0.05)
    return col + glow[..., None] * np.array([1.0, 0.92, 0.8])


# ----------------------------------------------------------------------------- assets

def assets() -> dict[str, bytes]:
    """Every asset file of the gallery: relative path -> bytes."""
    out: dict[str, bytes] = {}
    v, f, n, uv = cube_mesh()
    out["meshes/cube.obj"] = obj_text(v, f, n, uv, "cube [-1, 1]^3, flat normals, one uv square per face").encode()
    v, f, n, uv = torus_mesh(1.0, 0.35, 48, 24)
    out["meshes/torus.obj"] = obj_text(v, f, n, uv, "torus around Y: major radius 1, minor 0.35").encode()
    v, f, n, uv = tube_mesh(1.0, 2.0, 40)
    out["meshes/tube.obj"] = obj_text(v, f, n, uv, "open cylinder around Y, radius 1, y in [0, 2]").encode()
    v, f, n = blob_mesh()
    out["meshes/blob.ply"] = ply_bytes(v, f, n, binary=True, comment="bunny-like blob, flat bottom at y = 0")
    v, f = pedestal_mesh(1.0, 0.3, 32)
    out["meshes/pedestal.ply"] = ply_bytes(v, f, None, binary=False, comment="closed cylinder, radius 1, y in [0, 0.3]")
    for name, (v, f) in cornell_meshes().items():
        out[f"meshes/cbox_{name}.obj"] = obj_text(v, f, None, None, f"Cornell box: {name}").encode()
    out["textures/checker.png"] = png_bytes(checker_texture())
    out["textures/wood.png"] = png_bytes(wood_texture())
    out["textures/uvgrid.png"] = png_bytes(uvgrid_texture())
    out["textures/crate.png"] = png_bytes(crate_texture())
    out["envmaps/sky.exr"] = exr_bytes(sky_envmap())
    return out


def _quad(p0, p1, p2, p3):
    return [p0, p1, p2, p3], [(0, 1, 2), (0, 2, 3)]


def cornell_meshes():
    """The Cornell box in [-1, 1]^3, open towards +z: white (floor, ceiling, back), red (left), green (right).

    Quads wind so that their normals face into the box.
    """
    def merge(quads):
        v, f = [], []
        for qv, qf in quads:
            f += [tuple(i + len(v) for i in tri) for tri in qf]
            v += qv
        return np.array(v, dtype=float), np.array(f)

    floor = _quad((-1, -1, 1), (1, -1, 1), (1, -1, -1), (-1, -1, -1))
    ceiling = _quad((-1, 1, 1), (-1, 1, -1), (1, 1, -1), (1, 1, 1))
    back = _quad((-1, -1, -1), (1, -1, -1), (1, 1, -1), (-1, 1, -1))
    left = _quad((-1, -1, 1), (-1, -1, -1), (-1, 1, -1), (-1, 1, 1))
    right = _quad((1, -1, -1), (1, -1, 1), (1, 1, 1), (1, 1, -1))
    return {"white": merge([floor, ceiling, back]), "red": merge([left]), "green": merge([right])}


# ----------------------------------------------------------------------------- XML helpers

def fmt(x) -> str:
    """A number as Mitsuba XML text: short, no trailing zeros, no -0."""
    x = float(np.round(float(x), 6)) + 0.0
    s = f"{x:.6f}".rstrip("0").rstrip(".")
    return s if s not in ("", "-0") else "0"


def vec(p) -> str:
    return ", ".join(fmt(c) for c in p)


def rgb(name, value) -> str:
    if np.ndim(value) == 0:
        return f'<rgb name="{name}" value="{fmt(value)}"/>'
    return f'<rgb name="{name}" value="{vec(value)}"/>'


def to_world(*ops, name="to_world") -> str:
    """``<transform>`` with ops applied in order: ("scale", s|xyz), ("rotate", axis, deg), ("translate", xyz)."""
    parts = []
    for op in ops:
        if op[0] == "scale":
            s = op[1]
            parts.append(f'<scale value="{fmt(s)}"/>' if np.ndim(s) == 0
                         else f'<scale x="{fmt(s[0])}" y="{fmt(s[1])}" z="{fmt(s[2])}"/>')
        elif op[0] == "rotate":
            axis = "xyz"[op[1]] if isinstance(op[1], int) else op[1]
            parts.append(f'<rotate {axis}="1" angle="{fmt(op[2])}"/>')
        elif op[0] == "translate":
            t = op[1]
            parts.append(f'<translate x="{fmt(t[0])}" y="{fmt(t[1])}" z="{fmt(t[2])}"/>')
        elif op[0] == "lookat":
            parts.append(f'<lookat origin="{vec(op[1])}" target="{vec(op[2])}" up="{vec(op[3])}"/>')
        else:
            raise ValueError(op)
    return f'<transform name="{name}">' + "".join(parts) + "</transform>"


def indent(text: str, n: int) -> str:
    pad = " " * n
    return "\n".join(pad + line if line else line for line in text.split("\n"))


def bitmap(name, filename, extra="") -> str:
    return (f'<texture type="bitmap" name="{name}">'
            f'<string name="filename" value="{filename}"/>{extra}</texture>')


def sensor(origin, target, fov, *, sid="camera", rfilter=None, sampler="independent",
           film_extra="", up=(0, 1, 0), width="$res", height="$res") -> str:
    """A perspective sensor; ``rfilter=None`` leaves Mitsuba's default (gaussian)."""
    sampler_body = '<integer name="sample_count" value="$spp"/>'
    film = [f'<integer name="width" value="{width}"/>', f'<integer name="height" value="{height}"/>']
    if film_extra:
        film += film_extra.split("\n")
    if rfilter is not None:
        film.append(rfilter)
    return "\n".join([
        f'<sensor type="perspective" id="{sid}">',
        f'    <float name="fov" value="{fmt(fov)}"/>',
        f'    {to_world(("lookat", origin, target, up))}',
        f'    <sampler type="{sampler}">{sampler_body}</sampler>',
        '    <film type="hdrfilm">',
        *["        " + line for line in film],
        "    </film>",
        "</sensor>",
    ])


def shape(kind, sid, *body) -> str:
    inner = "\n".join("    " + b for b in body if b)
    return f'<shape type="{kind}" id="{sid}">\n{inner}\n</shape>'


def area_rect(sid, radiance, *ops) -> str:
    return shape("rectangle", sid, to_world(*ops),
                 f'<emitter type="area">{rgb("radiance", radiance)}</emitter>',
                 '<bsdf type="diffuse">' + rgb("reflectance", 0.0) + "</bsdf>")


def area_sphere(sid, center, radius, radiance) -> str:
    return shape("sphere", sid, f'<point name="center" value="{vec(center)}"/>',
                 f'<float name="radius" value="{fmt(radius)}"/>',
                 f'<emitter type="area">{rgb("radiance", radiance)}</emitter>')


def diffuse(value) -> str:
    return f'<bsdf type="diffuse">{rgb("reflectance", value)}</bsdf>'


def sphere(sid, center, radius, bsdf) -> str:
    return shape("sphere", sid, f'<point name="center" value="{vec(center)}"/>',
                 f'<float name="radius" value="{fmt(radius)}"/>', bsdf)


def scene_xml(name, summary, features, body) -> str:
    feat = "\n".join("    - " + f for f in features)
    return f"""<?xml version="1.0" encoding="utf-8"?>
<!--
  Generated by tools/make_gallery.py; do not edit by hand (rerun the script).
  {name}: {summary}
  Uses:
{feat}
  Parameters (override with mi.load_file(path, name=value)):
    res        film width and height in pixels
    spp        samples per pixel
    max_depth  longest path of the path integrator
-->
<scene version="3.0.0">
    <default name="res" value="128"/>
    <default name="spp" value="64"/>
    <default name="max_depth" value="8"/>

    <integrator type="path">
        <integer name="max_depth" value="$max_depth"/>
    </integrator>

{indent(body.strip(), 4)}
</scene>
"""


# ----------------------------------------------------------------------------- scenes

def room():
    depth, mid = 3.75, 1.75  # the room spans z in [-2, 5.5], open behind the camera
    body = "\n\n".join([
        sensor((0, 1.45, 5.2), (0, 0.75, 0), 42),
        shape("rectangle", "floor",
              to_world(("scale", (2, depth, 1)), ("rotate", 0, -90), ("translate", (0, 0, mid))),
              '<bsdf type="diffuse">' + bitmap(
                  "reflectance", "textures/wood.png",
                  to_world(("scale", (2, depth, 1)), name="to_uv")) + "</bsdf>"),
        shape("rectangle", "ceiling",
              to_world(("scale", (2, depth, 1)), ("rotate", 0, 90), ("translate", (0, 3, mid))),
              diffuse(0.8)),
        shape("rectangle", "back_wall", to_world(("scale", (2, 1.5, 1)), ("translate", (0, 1.5, -2))),
              diffuse((0.75, 0.72, 0.65))),
        shape("rectangle", "left_wall",
              to_world(("scale", (depth, 1.5, 1)), ("rotate", 1, 90), ("translate", (-2, 1.5, mid))),
              diffuse((0.65, 0.3, 0.25))),
        shape("rectangle", "right_wall",
              to_world(("scale", (depth, 1.5, 1)), ("rotate", 1, -90), ("translate", (2, 1.5, mid))),
              diffuse((0.3, 0.45, 0.65))),
        area_rect("ceiling_light", 12.0, ("scale", 0.6), ("rotate", 0, 90), ("translate", (0, 2.99, -0.3))),
        sphere("glass_sphere", (-0.95, 0.5, 0.2), 0.5,
               '<bsdf type="dielectric"><string name="int_ior" value="bk7"/>'
               '<string name="ext_ior" value="air"/></bsdf>'),
        shape("obj", "plastic_cube", '<string name="filename" value="meshes/cube.obj"/>',
              to_world(("scale", 0.38), ("rotate", 1, 30), ("translate", (0.15, 0.38, -0.9))),
              '<bsdf type="plastic">' + rgb("diffuse_reflectance", (0.1, 0.25, 0.7))
              + '<float name="int_ior" value="1.5"/></bsdf>'),
        shape("obj", "copper_torus", '<string name="filename" value="meshes/torus.obj"/>',
              to_world(("scale", 0.42), ("rotate", 0, 70), ("rotate", 1, -35), ("translate", (1.05, 0.55, 0.3))),
              '<bsdf type="roughconductor"><string name="material" value="Cu"/>'
              '<string name="distribution" value="ggx"/><float name="alpha" value="0.15"/></bsdf>'),
    ])
    return scene_xml(
        "room", "a room with a wooden floor, a ceiling light, a glass sphere, a plastic cube and a copper torus",
        ["diffuse with a bitmap texture (textures/wood.png, to_uv scaled)",
         "area emitter on a rectangle", "dielectric, plastic, roughconductor (Cu, ggx)",
         "OBJ meshes (meshes/cube.obj, meshes/torus.obj)",
         "hdrfilm with Mitsuba's default reconstruction filter (gaussian)", "independent sampler"],
        body)


ENV = '<emitter type="envmap" id="sky"><string name="filename" value="envmaps/sky.exr"/>' \
      '<float name="scale" value="{scale}"/></emitter>'


def envmap_objects():
    body = "\n\n".join([
        sensor((0, 1.3, 4.6), (0, 0.55, 0), 40, film_extra='<string name="pixel_format" value="rgba"/>'),
        ENV.format(scale=fmt(1.0)),
        shape("disk", "ground", to_world(("scale", 3.5), ("rotate", 0, -90)), diffuse(0.45)),
        shape("ply", "blob", '<string name="filename" value="meshes/blob.ply"/>',
              to_world(("scale", 0.6), ("rotate", 1, -60), ("translate", (0, 0, -0.3))),
              '<bsdf type="roughplastic">' + rgb("diffuse_reflectance", (0.75, 0.55, 0.35))
              + '<string name="distribution" value="ggx"/><float name="alpha" value="0.2"/></bsdf>'),
        sphere("glass_ball", (-1.25, 0.45, 0.35), 0.45,
               '<bsdf type="dielectric"><float name="int_ior" value="1.5"/></bsdf>'),
        sphere("gold_ball", (1.25, 0.45, 0.3), 0.45,
               '<bsdf type="roughconductor"><string name="material" value="Au"/>'
               '<float name="alpha" value="0.08"/></bsdf>'),
    ])
    return scene_xml(
        "envmap_objects", "a bunny-like blob between a glass and a gold ball, lit by a sky",
        ["envmap emitter (envmaps/sky.exr, half-float lat-long)",
         "PLY mesh (meshes/blob.ply, binary, with vertex normals)",
         "roughplastic (ggx), dielectric, roughconductor (Au, beckmann)", "disk shape",
         "rgba film (pixel_format rgba)", "default (gaussian) filter, independent sampler"],
        body)


def cornell():
    def obj(sid, part, bsdf_ref):
        return shape("obj", sid, f'<string name="filename" value="meshes/cbox_{part}.obj"/>',
                     f'<ref id="{bsdf_ref}"/>')

    body = "\n\n".join([
        sensor((0, 0, 3.9), (0, 0, 0), 39, rfilter='<rfilter type="tent"/>'),
        diffuse((0.73, 0.73, 0.73)).replace('<bsdf type="diffuse">', '<bsdf type="diffuse" id="white">'),
        diffuse((0.63, 0.065, 0.05)).replace('<bsdf type="diffuse">', '<bsdf type="diffuse" id="red">'),
        diffuse((0.14, 0.45, 0.091)).replace('<bsdf type="diffuse">', '<bsdf type="diffuse" id="green">'),
        obj("cbox_white", "white", "white"),
        obj("cbox_left", "red", "red"),
        obj("cbox_right", "green", "green"),
        area_rect("cbox_light", (13.0, 11.0, 5.6), ("scale", 0.3), ("rotate", 0, 90), ("translate", (0, 0.995, 0))),
        sphere("mirror_sphere", (-0.45, -0.65, -0.35), 0.35, '<bsdf type="conductor"/>'),
        sphere("glass_sphere", (0.45, -0.65, 0.25), 0.35,
               '<bsdf type="dielectric"><float name="int_ior" value="1.5"/></bsdf>'),
    ])
    return scene_xml(
        "cornell", "the Cornell box with a mirror and a glass sphere",
        ["OBJ meshes for the walls (meshes/cbox_*.obj), shared BSDFs by id and ref",
         "area emitter on a rectangle", "conductor (perfect mirror, material none), dielectric",
         "tent reconstruction filter", "independent sampler"],
        body)


def checker_border():
    body = "\n\n".join([
        sensor((0, 1.1, 3.6), (0, 0.45, 0), 45),
        '<emitter type="constant" id="ambient">' + rgb("radiance", 0.25) + "</emitter>",
        area_sphere("sphere_light", (-2.0, 3.2, 1.5), 0.4, 30.0),
        shape("rectangle", "checker_floor",
              to_world(("scale", 6), ("rotate", 0, -90)),
              '<bsdf type="diffuse">' + bitmap(
                  "reflectance", "textures/checker.png",
                  '<string name="filter_type" value="nearest"/>'
                  + to_world(("scale", (3, 3, 1)), name="to_uv")) + "</bsdf>"),
        shape("obj", "diffuse_cube", '<string name="filename" value="meshes/cube.obj"/>',
              to_world(("scale", 0.4), ("rotate", 1, 20), ("translate", (-0.75, 0.4, -0.4))),
              diffuse((0.8, 0.35, 0.15))),
        shape("ply", "principled_blob", '<string name="filename" value="meshes/blob.ply"/>',
              to_world(("scale", 0.5), ("rotate", 1, -120), ("translate", (0.8, 0, 0.1))),
              '<bsdf type="principled">' + rgb("base_color", (0.2, 0.5, 0.8))
              + '<float name="metallic" value="0.3"/><float name="roughness" value="0.35"/>'
              '<float name="clearcoat" value="0.6"/></bsdf>'),
    ])
    return scene_xml(
        "checker_border", "a high-contrast checkerboard floor running to the image's bottom border",
        ["diffuse with a bitmap texture (textures/checker.png, nearest filtering): black and white "
         "squares fill the bottom rows of the image",
         "area emitter on a sphere, constant emitter", "diffuse (OBJ cube), principled (PLY blob)",
         "default (gaussian) filter, independent sampler"],
        body)


def instanced():
    cups = []
    for i in range(5):
        for j in range(5):
            x, z = (i - 2) * 0.9, (j - 2) * 0.9
            tilt = 12.0 * ((i * 3 + j * 7) % 5 - 2)
            spin = 37.0 * (i * 5 + j)
            scale = 0.8 + 0.05 * ((i + 2 * j) % 4)
            cups.append(shape("instance", f"cup_{i}_{j}", '<ref id="cup"/>',
                              to_world(("scale", scale), ("rotate", 1, spin), ("rotate", 0, tilt),
                                       ("translate", (x, 0.25 * scale, z)))))
    group = "\n".join([
        '<shape type="shapegroup" id="cup">',
        indent(shape("obj", "cup_wall", '<string name="filename" value="meshes/tube.obj"/>',
                     to_world(("scale", (0.28, 0.2, 0.28))),
                     '<bsdf type="twosided"><bsdf type="diffuse">' + rgb("reflectance", (0.85, 0.8, 0.6))
                     + "</bsdf></bsdf>"), 4),
        indent(sphere("cup_ball", (0, 0.12, 0), 0.14,
                      '<bsdf type="plastic">' + rgb("diffuse_reflectance", (0.8, 0.15, 0.1)) + "</bsdf>"), 4),
        "</shape>",
    ])
    body = "\n\n".join([
        sensor((0, 3.6, 4.2), (0, 0, 0.1), 42, rfilter='<rfilter type="box"/>', sampler="stratified"),
        area_rect("top_light", 5.0, ("scale", 1.5), ("rotate", 0, 90), ("translate", (-1, 4, 1))),
        shape("rectangle", "table", to_world(("scale", 3), ("rotate", 0, -90)), diffuse((0.35, 0.4, 0.45))),
        group,
        *cups,
    ])
    return scene_xml(
        "instanced", "a 5 x 5 grid of instances of one shapegroup (an open cup holding a ball)",
        ["shapegroup + 25 instances", "twosided wrapping diffuse (the open cylinder, meshes/tube.obj)",
         "plastic, area emitter on a rectangle", "box reconstruction filter", "stratified sampler"],
        body)


def materials():
    rows = [
        ("diffuse", diffuse((0.7, 0.2, 0.15))),
        ("plastic", '<bsdf type="plastic">' + rgb("diffuse_reflectance", (0.1, 0.3, 0.8)) + "</bsdf>"),
        ("roughplastic", '<bsdf type="roughplastic">' + rgb("diffuse_reflectance", (0.15, 0.6, 0.2))
         + '<float name="alpha" value="0.25"/></bsdf>'),
        ("conductor", '<bsdf type="conductor"><string name="material" value="Al"/></bsdf>'),
        ("roughconductor", '<bsdf type="roughconductor"><string name="material" value="Cu"/>'
         '<float name="alpha" value="0.25"/></bsdf>'),
        ("dielectric", '<bsdf type="dielectric"><float name="int_ior" value="1.5"/></bsdf>'),
        ("principled", '<bsdf type="principled">' + rgb("base_color", (0.9, 0.75, 0.2))
         + '<float name="metallic" value="0.7"/><float name="roughness" value="0.3"/></bsdf>'),
        ("blendbsdf", '<bsdf type="blendbsdf">'
         + bitmap("weight", "textures/checker.png", '<boolean name="raw" value="true"/>')
         + diffuse((0.8, 0.8, 0.8))
         + '<bsdf type="conductor"><string name="material" value="Au"/></bsdf></bsdf>'),
    ]
    spheres = []
    for k, (name, bsdf) in enumerate(rows):
        row, col = divmod(k, 4)
        x = (col - 1.5) * 1.1 + (row - 0.5) * 0.55  # back row staggered by half a step
        spheres.append(sphere(f"sphere_{name}", (x, 0.45, -row * 1.2), 0.45, bsdf))
    body = "\n\n".join([
        sensor((0, 3.4, 6.6), (0, 0.25, -0.6), 36,
               rfilter='<rfilter type="gaussian"><float name="stddev" value="0.5"/></rfilter>'),
        ENV.format(scale=fmt(1.0)),
        shape("rectangle", "ground", to_world(("scale", 8), ("rotate", 0, -90)), diffuse(0.5)),
        *spheres,
    ])
    return scene_xml(
        "materials", "two rows of spheres, one BSDF each, under a sky",
        ["diffuse, plastic, roughplastic, conductor (Al), roughconductor (Cu), dielectric, "
         "principled, blendbsdf (diffuse / Au conductor, weighted by textures/checker.png, raw)",
         "envmap emitter (envmaps/sky.exr)", "explicit gaussian reconstruction filter (stddev 0.5)",
         "independent sampler"],
        body)


def crop_rgba():
    crop = "\n".join(['<integer name="crop_offset_x" value="$crop_x"/>',
                      '<integer name="crop_offset_y" value="$crop_y"/>',
                      '<integer name="crop_width" value="$res"/>',
                      '<integer name="crop_height" value="$res"/>',
                      '<string name="pixel_format" value="rgba"/>'])
    body = "\n\n".join([
        sensor((0, 1.6, 4.2), (-0.45, 0.95, 0), 40, film_extra=crop, width="$film_res", height="$film_res"),
        area_rect("key_light", 12.0, ("scale", 0.8), ("lookat", (-1.5, 3.2, 2.4), (0, 0.5, 0), (0, 1, 0))),
        area_rect("fill_light", 3.0, ("scale", 1.2), ("lookat", (3.5, 1.5, 1.0), (0, 0.5, 0), (0, 1, 0))),
        shape("ply", "pedestal", '<string name="filename" value="meshes/pedestal.ply"/>',
              to_world(("scale", (1.5, 1.0, 1.5))), diffuse(0.6)),
        shape("obj", "torus", '<string name="filename" value="meshes/torus.obj"/>',
              to_world(("scale", 0.45), ("rotate", 0, 90), ("translate", (-0.5, 0.92, 0))),
              '<bsdf type="roughconductor"><string name="material" value="Cu"/>'
              '<float name="alpha" value="0.2"/></bsdf>'),
        shape("obj", "crate", '<string name="filename" value="meshes/cube.obj"/>',
              to_world(("scale", 0.3), ("rotate", 1, 25), ("translate", (0.55, 0.6, 0.2))),
              '<bsdf type="diffuse">' + bitmap("reflectance", "textures/crate.png") + "</bsdf>"),
    ])
    xml = scene_xml(
        "crop_rgba", "objects on a pedestal, rendered through a crop window of an rgba film "
        "(transparent background)",
        ["film crop window (crop_offset_x/y, crop_width/height)", "rgba film: alpha 0 where no shape is hit",
         "area emitters on rectangles (not seen by the camera)", "PLY mesh, ASCII (meshes/pedestal.ply)",
         "roughconductor (Cu), diffuse with a bitmap texture (textures/crate.png)",
         "default (gaussian) filter, independent sampler"],
        body)
    extra = ('    <default name="film_res" value="256"/>\n'
             '    <default name="crop_x" value="80"/>\n'
             '    <default name="crop_y" value="88"/>\n')
    xml = xml.replace('    <default name="max_depth" value="8"/>\n',
                      '    <default name="max_depth" value="8"/>\n' + extra)
    return xml.replace(
        "    res        film width and height in pixels\n",
        "    res        crop window width and height in pixels (the image rendered)\n"
        "    film_res   full film width and height (>= crop_x + res and crop_y + res)\n"
        "    crop_x/y   crop window's offset in the full film\n")


def two_sensors():
    body = "\n\n".join([
        sensor((0.8, 1.4, 4.0), (0, 0.5, 0), 40, sid="front"),
        sensor((4.0, 2.0, -1.2), (0, 0.5, 0), 40, sid="side"),
        '<emitter type="constant" id="ambient">' + rgb("radiance", 0.15) + "</emitter>",
        area_rect("light", 10.0, ("scale", 0.7), ("rotate", 0, 90), ("translate", (1.0, 3.5, 1.0))),
        shape("rectangle", "ground", to_world(("scale", 5), ("rotate", 0, -90)), diffuse((0.55, 0.55, 0.5))),
        shape("ply", "blob", '<string name="filename" value="meshes/blob.ply"/>',
              to_world(("scale", 0.55), ("rotate", 1, 20), ("translate", (-0.4, 0, -0.2))),
              '<bsdf type="roughplastic">' + rgb("diffuse_reflectance", (0.8, 0.55, 0.5))
              + '<float name="alpha" value="0.3"/></bsdf>'),
        shape("obj", "cube", '<string name="filename" value="meshes/cube.obj"/>',
              to_world(("scale", 0.3), ("rotate", 1, 15), ("translate", (0.7, 0.3, 0.4))),
              '<bsdf type="diffuse">' + bitmap("reflectance", "textures/uvgrid.png") + "</bsdf>"),
        shape("obj", "torus", '<string name="filename" value="meshes/torus.obj"/>',
              to_world(("scale", 0.35), ("translate", (0.6, 0.12, -0.8))),
              '<bsdf type="roughconductor"><string name="material" value="Au"/>'
              '<float name="alpha" value="0.2"/></bsdf>'),
    ])
    return scene_xml(
        "two_sensors", "a blob, a cube and a torus seen by two cameras (front, side)",
        ["two perspective sensors (ids front and side; mi.render(scene, sensor=1) renders the second)",
         "constant emitter, area emitter on a rectangle", "PLY and OBJ meshes",
         "roughplastic, roughconductor (Au), diffuse with a bitmap texture (textures/uvgrid.png)",
         "default (gaussian) filter, independent sampler"],
        body)


def spot_textures():
    body = "\n\n".join([
        sensor((-0.6, 1.5, 4.0), (0.1, 0.5, 0), 42, sampler="multijitter"),
        '<emitter type="constant" id="ambient">' + rgb("radiance", 0.08) + "</emitter>",
        '<emitter type="spot" id="spot">'
        + to_world(("lookat", (2.0, 3.5, 2.5), (0.2, 0.3, 0), (0, 1, 0)))
        + rgb("intensity", 40.0) + '<float name="cutoff_angle" value="28"/>'
        '<float name="beam_width" value="20"/></emitter>',
        '<emitter type="point" id="fill">' + f'<point name="position" value="{vec((-2.5, 2.5, 1.5))}"/>'
        + rgb("intensity", (4.0, 5.0, 7.0)) + "</emitter>",
        shape("rectangle", "floor", to_world(("scale", 4), ("rotate", 0, -90)),
              '<bsdf type="diffuse">' + bitmap("reflectance", "textures/wood.png",
                                               to_world(("scale", (4, 4, 1)), name="to_uv")) + "</bsdf>"),
        shape("rectangle", "back_wall", to_world(("scale", (4, 2, 1)), ("translate", (0, 2, -2))),
              diffuse((0.6, 0.6, 0.6))),
        shape("obj", "crate", '<string name="filename" value="meshes/cube.obj"/>',
              to_world(("scale", 0.45), ("rotate", 1, 35), ("translate", (-0.55, 0.45, -0.3))),
              '<bsdf type="diffuse">' + bitmap("reflectance", "textures/crate.png") + "</bsdf>"),
        sphere("globe", (0.75, 0.42, 0.3), 0.42,
               '<bsdf type="diffuse">' + bitmap("reflectance", "textures/uvgrid.png") + "</bsdf>"),
    ])
    return scene_xml(
        "spot_textures", "textured crate and globe under a spot light",
        ["spot and point emitters (delta lights), constant emitter",
         "diffuse with bitmap textures (wood, crate, uvgrid) on an OBJ cube, a sphere, a rectangle",
         "default (gaussian) filter, multijitter sampler"],
        body)


SCENES = {
    "room": room,
    "envmap_objects": envmap_objects,
    "cornell": cornell,
    "checker_border": checker_border,
    "instanced": instanced,
    "materials": materials,
    "crop_rgba": crop_rgba,
    "two_sensors": two_sensors,
    "spot_textures": spot_textures,
}


def gallery_files() -> dict[str, bytes]:
    """Every file of the gallery: relative path -> bytes."""
    files = assets()
    for name, make in SCENES.items():
        files[f"{name}.xml"] = make().encode("utf-8")
    return files


def write_gallery(out=DEFAULT_OUT) -> list[Path]:
    """Write the gallery into ``out``; returns the paths written."""
    out = Path(out)
    written = []
    for rel, data in sorted(gallery_files().items()):
        path = out / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)
        written.append(path)
    return written


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", default=str(DEFAULT_OUT), help="output folder (default: scenes_xml/gallery)")
    args = parser.parse_args(argv)
    paths = write_gallery(args.out)
    print(f"wrote {len(paths)} files into {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
