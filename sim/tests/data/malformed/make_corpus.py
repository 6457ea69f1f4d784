#!/usr/bin/env python3
"""Regenerates the malformed-input corpus used by sim/tests/mesh_io.rs (malformed_corpus).

Run from anywhere: python3 sim/tests/data/malformed/make_corpus.py
Standard library only. Each file is tiny and broken in exactly one way; README.md lists them
with the error the readers must return.
"""
import base64
import json
import os
import struct

HERE = os.path.dirname(os.path.abspath(__file__))

CUBE_V = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]
# Outward (counter-clockwise seen from outside) quads, split into two triangles each.
CUBE_Q = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (2, 3, 7, 6), (1, 2, 6, 5), (0, 4, 7, 3)]
CUBE_F = [t for q in CUBE_Q for t in ((q[0], q[1], q[2]), (q[0], q[2], q[3]))]

TET_V = [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)]
TET_F = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]


def write(name, data):
    mode = "wb" if isinstance(data, bytes) else "w"
    with open(os.path.join(HERE, name), mode) as f:
        f.write(data)


def obj(verts, faces, header):
    lines = [f"# {header}"]
    lines += [f"v {x} {y} {z}" for x, y, z in verts]
    lines += ["f " + " ".join(str(i + 1) for i in f) for f in faces]
    return "\n".join(lines) + "\n"


def gltf_parts(verts, faces, index_fix=None):
    """(json dict, bin bytes) of one indexed triangle primitive."""
    pos = b"".join(struct.pack("<3f", *v) for v in verts)
    flat = [i for f in faces for i in f]
    if index_fix:
        flat[index_fix[0]] = index_fix[1]
    idx = struct.pack(f"<{len(flat)}H", *flat)
    pad = (-len(idx)) % 4
    binary = pos + idx + b"\0" * pad
    lo = [min(v[k] for v in verts) for k in range(3)]
    hi = [max(v[k] for v in verts) for k in range(3)]
    doc = {
        "asset": {"version": "2.0", "generator": "heatsim make_corpus.py"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "mode": 4}]}],
        "buffers": [{"byteLength": len(binary)}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": len(pos), "target": 34962},
            {"buffer": 0, "byteOffset": len(pos), "byteLength": len(idx), "target": 34963},
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": len(verts), "type": "VEC3",
             "min": lo, "max": hi},
            {"bufferView": 1, "componentType": 5123, "count": len(flat), "type": "SCALAR"},
        ],
    }
    return doc, binary


def glb(doc, binary):
    js = json.dumps(doc, separators=(",", ":")).encode()
    js += b" " * ((-len(js)) % 4)
    body = struct.pack("<I4s", len(js), b"JSON") + js + struct.pack("<I4s", len(binary), b"BIN\0") + binary
    return struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body


def data_uri(doc, binary):
    doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(binary).decode()
    return json.dumps(doc, indent=1) + "\n"


def main():
    # --- OBJ ---
    cube = obj(CUBE_V, CUBE_F, "unit cube")
    write("truncated.obj", cube[: cube.index("v 1 1 1") + len("v 1 1")])
    write("bad_index.obj", obj(TET_V, TET_F[:3] + [(1, 2, 8)], "tetrahedron whose last face uses vertex 9 of 4"))
    write("nan.obj", obj(TET_V, TET_F, "tetrahedron").replace("v 1 0 0", "v nan 0 0"))
    write("inf.obj", obj(TET_V, TET_F, "tetrahedron").replace("v 0 1 0", "v 0 1e999 0"))
    write("empty.obj", "")
    write("garbage.obj", bytes((i * 37 + 11) % 256 for i in range(512)))
    write("two_vertex_face.obj", obj(TET_V, TET_F, "tetrahedron").rstrip("\n") + "\nf 1 2\n")
    write("zero_index.obj", obj(TET_V, TET_F, "tetrahedron").replace("f 1 3 2", "f 0 3 2"))
    write("open.obj", obj(CUBE_V, CUBE_F[:-2], "unit cube without its x = 0 side"))
    write("inside_out.obj", obj(CUBE_V, [(a, c, b) for a, b, c in CUBE_F], "unit cube wound inwards"))
    tet2 = [(x + 0.25, y + 0.25, z + 0.25) for x, y, z in TET_V]
    write("self_intersecting.obj",
          obj(TET_V + tet2, TET_F + [tuple(i + 4 for i in f) for f in TET_F], "two interpenetrating tetrahedra"))
    write("unsupported.stl", "solid nothing\nendsolid nothing\n")

    # --- glTF ---
    doc, binary = gltf_parts(TET_V, TET_F)
    full = glb(doc, binary)
    write("truncated.glb", full[: len(full) // 2])
    bad_len = bytearray(full)
    bad_len[8:12] = struct.pack("<I", 4)
    write("bad_length.glb", bytes(bad_len))
    doc, binary = gltf_parts(TET_V, TET_F, index_fix=(11, 7))
    write("bad_index.gltf", data_uri(doc, binary))
    doc, binary = gltf_parts(TET_V, TET_F)
    doc["buffers"][0]["uri"] = "missing_buffer.bin"
    write("missing_buffer.gltf", json.dumps(doc, indent=1) + "\n")
    doc, binary = gltf_parts(TET_V, TET_F)
    doc["meshes"][0]["primitives"][0]["mode"] = 1
    write("lines_mode.gltf", data_uri(doc, binary))
    doc, binary = gltf_parts(TET_V, TET_F)
    doc["accessors"][1]["count"] = 30
    write("accessor_overrun.gltf", data_uri(doc, binary))
    doc, binary = gltf_parts(TET_V, TET_F)
    doc["nodes"] = [{"mesh": 0, "children": [1]}, {"children": [0]}]
    write("node_cycle.gltf", data_uri(doc, binary))
    write("not_json.gltf", '{"asset": {"version": "2.0"}, "meshes": [\n')


if __name__ == "__main__":
    main()
