#!/usr/bin/env python3
"""Writes grid.gltf: the uncompressed source of the Draco fixtures beside it (see make.sh).

A 24 x 24 vertex height field (1058 triangles: over the 1000 below which Draco's
encoder never uses the valence traversal) with NORMAL, TEXCOORD_0 and COLOR_0, textured
by a 2 x 2 PNG with a tint, plus a second primitive (a quad, POSITION and indices only, a
plain colour material); mesh 0 is placed twice: translated, rotated and scaled, and
mirrored (scale -1 in x), so transforms and the winding flip are checked through Draco.
"""
import base64, json, math, struct, zlib

N = 24
pos, nrm, uv, col = [], [], [], []
for j in range(N):
    for i in range(N):
        x, y = i / (N - 1), j / (N - 1)
        z = 0.1 * math.sin(3 * x) * math.cos(2 * y)
        dzdx = 0.3 * math.cos(3 * x) * math.cos(2 * y)
        dzdy = -0.2 * math.sin(3 * x) * math.sin(2 * y)
        n = (-dzdx, -dzdy, 1.0)
        l = math.sqrt(sum(c * c for c in n))
        pos.append((x, y, z))
        nrm.append(tuple(c / l for c in n))
        uv.append((x, 1 - y))
        col.append((x, y, 1 - x, 1.0))
idx = []
for j in range(N - 1):
    for i in range(N - 1):
        a = j * N + i
        idx += [a, a + 1, a + N + 1, a, a + N + 1, a + N]
quad = [(0, 0, 0.5), (1, 0, 0.5), (1, 1, 0.6), (0, 1, 0.6)]
quad_idx = [0, 1, 2, 0, 2, 3]

bin_ = bytearray()
views, accessors = [], []


def add(data, fmt, count, ctype, type_, target, minmax=None):
    while len(bin_) % 4:
        bin_.append(0)
    start = len(bin_)
    for d in data:
        bin_.extend(struct.pack(fmt, *(d if isinstance(d, tuple) else (d,))))
    views.append({"buffer": 0, "byteOffset": start, "byteLength": len(bin_) - start, "target": target})
    a = {"bufferView": len(views) - 1, "componentType": ctype, "count": count, "type": type_}
    if minmax:
        a["min"] = [min(p[k] for p in data) for k in range(3)]
        a["max"] = [max(p[k] for p in data) for k in range(3)]
    accessors.append(a)
    return len(accessors) - 1


P = add(pos, "<3f", len(pos), 5126, "VEC3", 34962, True)
Nn = add(nrm, "<3f", len(nrm), 5126, "VEC3", 34962)
T = add(uv, "<2f", len(uv), 5126, "VEC2", 34962)
C = add(col, "<4f", len(col), 5126, "VEC4", 34962)
I = add(idx, "<H", len(idx), 5123, "SCALAR", 34963)
QP = add(quad, "<3f", len(quad), 5126, "VEC3", 34962, True)
QI = add(quad_idx, "<H", len(quad_idx), 5123, "SCALAR", 34963)


def png(w, h, rgb):
    raw = b"".join(b"\x00" + bytes(c for px in rgb[y * w:(y + 1) * w] for c in px) for y in range(h))
    def chunk(t, d):
        return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xFFFFFFFF)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


image = png(2, 2, [(255, 0, 0), (0, 255, 0), (0, 0, 255), (255, 255, 255)])
c, s = math.cos(0.3), math.sin(0.3)
doc = {
    "asset": {"version": "2.0", "generator": "tessera make_grid.py"},
    "scene": 0,
    "scenes": [{"nodes": [0, 1]}],
    "nodes": [
        {"mesh": 0, "translation": [1, 2, 3], "rotation": [0, 0, math.sin(0.15), math.cos(0.15)], "scale": [2, 2, 2]},
        {"mesh": 0, "scale": [-1, 1, 1]},
    ],
    "meshes": [{"primitives": [
        {"attributes": {"POSITION": P, "NORMAL": Nn, "TEXCOORD_0": T, "COLOR_0": C}, "indices": I, "material": 0, "mode": 4},
        {"attributes": {"POSITION": QP}, "indices": QI, "material": 1, "mode": 4},
    ]}],
    "materials": [
        {"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "baseColorFactor": [1, 0.5, 1, 1]}},
        {"pbrMetallicRoughness": {"baseColorFactor": [0.2, 0.4, 0.6, 1]}},
    ],
    "textures": [{"source": 0, "sampler": 0}],
    "samplers": [{"wrapS": 33071, "wrapT": 10497}],
    "images": [{"uri": "data:image/png;base64," + base64.b64encode(image).decode()}],
    "accessors": accessors,
    "bufferViews": views,
    "buffers": [{"byteLength": len(bin_), "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(bin_)).decode()}],
}
with open("grid.gltf", "w") as f:
    json.dump(doc, f, indent=1)
