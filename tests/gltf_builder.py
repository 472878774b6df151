"""Build small glTF documents in memory for loader tests (data-URI buffers or GLB)."""

from __future__ import annotations

import base64
import copy
import json
import struct
from pathlib import Path
from typing import Any, Optional

import numpy as np

TRIANGLES, POINTS, LINES, STRIP, FAN = 4, 0, 1, 5, 6


def document(
    positions: np.ndarray, indices: Optional[np.ndarray] = None, mode: int = TRIANGLES
) -> dict[str, Any]:
    """One mesh, one node, one scene; accessor 0 is POSITION, accessor 1 the indices."""
    pos = np.ascontiguousarray(positions, dtype=np.float32)
    blob = pos.tobytes()
    views = [{"buffer": 0, "byteOffset": 0, "byteLength": len(blob)}]
    accessors: list[dict[str, Any]] = [
        {"bufferView": 0, "componentType": 5126, "count": len(pos), "type": "VEC3"},
    ]
    prim: dict[str, Any] = {"attributes": {"POSITION": 0}, "mode": mode}
    if indices is not None:
        idx = np.ascontiguousarray(indices, dtype=np.uint32).ravel().tobytes()
        views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": len(idx)})
        accessors.append(
            {"bufferView": 1, "componentType": 5125, "count": len(idx) // 4, "type": "SCALAR"}
        )
        prim["indices"] = 1
        blob += idx
    return {
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": len(blob), "uri": data_uri(blob)}],
        "bufferViews": views,
        "accessors": accessors,
        "meshes": [{"primitives": [prim]}],
        "nodes": [{"mesh": 0}],
        "scenes": [{"nodes": [0]}],
        "scene": 0,
    }


def data_uri(blob: bytes, mime: str = "application/octet-stream") -> str:
    return f"data:{mime};base64," + base64.b64encode(blob).decode()


def add_accessor(doc: dict[str, Any], data: np.ndarray, type_: str) -> int:
    """Append `data` (float32) as a new buffer + view + accessor; returns the accessor index."""
    blob = np.ascontiguousarray(data, dtype=np.float32).tobytes()
    doc["buffers"].append({"byteLength": len(blob), "uri": data_uri(blob)})
    doc["bufferViews"].append({"buffer": len(doc["buffers"]) - 1, "byteLength": len(blob)})
    doc["accessors"].append(
        {
            "bufferView": len(doc["bufferViews"]) - 1,
            "componentType": 5126,
            "count": len(data),
            "type": type_,
        }
    )
    return len(doc["accessors"]) - 1


def write(doc: dict[str, Any], path: Path) -> Path:
    path.write_text(json.dumps(doc))
    return path


def to_glb(doc: dict[str, Any]) -> bytes:
    """The same document as a GLB with buffer 0 moved into the BIN chunk."""
    doc = copy.deepcopy(doc)
    uri = doc["buffers"][0].pop("uri")
    binary = base64.b64decode(uri.split(",", 1)[1])
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    binary += b"\0" * (-len(binary) % 4)
    chunks = (
        struct.pack("<I4s", len(js), b"JSON")
        + js
        + struct.pack("<I4s", len(binary), b"BIN\0")
        + binary
    )
    return struct.pack("<4sII", b"glTF", 2, 12 + len(chunks)) + chunks


TRI = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=np.float32)
QUAD = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=np.float32)
