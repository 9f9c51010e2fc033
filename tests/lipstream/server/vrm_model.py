"""A small VRM 1.0 avatar written from the published formats, for the VRM page's tests.

A glTF 2.0 binary (GLB: a 12-byte header, then a JSON chunk and a BIN chunk, each padded
to 4 bytes) whose ``VRMC_vrm`` extension (specVersion 1.0) holds the meta with the VRM
1.0 licence URL, a humanoid with the 15 bones VRM 1.0 requires, and one expression per
name in ``expressions`` (a preset where VRM 1.0 names one, else custom), each bound (``morphTargetBinds``) to the face mesh's morph
target of the same name with weight 1. One more morph target, ``unbound``, is bound to
no expression. Each target lifts its own vertex of the face, so a drawn frame shows it.
"""

from __future__ import annotations

import json
import struct
from collections.abc import Sequence

import numpy as np

GLB_MAGIC = 0x46546C67  # "glTF"
CHUNK_JSON = 0x4E4F534A
CHUNK_BIN = 0x004E4942
FLOAT = 5126
UNSIGNED_SHORT = 5123
ARRAY_BUFFER = 34962
ELEMENT_ARRAY_BUFFER = 34963
VRM_LICENCE_URL = "https://vrm.dev/licenses/1.0/"
UNBOUND_TARGET = "unbound"
VRM1_PRESETS = frozenset(
    "happy angry sad relaxed surprised aa ih ou ee oh blink blinkLeft blinkRight"
    " lookUp lookDown lookLeft lookRight neutral".split()
)

# bone: (parent, offset from the parent in metres)
SKELETON: dict[str, tuple[str | None, tuple[float, float, float]]] = {
    "hips": (None, (0.0, 0.9, 0.0)),
    "spine": ("hips", (0.0, 0.15, 0.0)),
    "head": ("spine", (0.0, 0.5, 0.0)),
    "leftUpperArm": ("spine", (0.18, 0.4, 0.0)),
    "leftLowerArm": ("leftUpperArm", (0.25, 0.0, 0.0)),
    "leftHand": ("leftLowerArm", (0.25, 0.0, 0.0)),
    "rightUpperArm": ("spine", (-0.18, 0.4, 0.0)),
    "rightLowerArm": ("rightUpperArm", (-0.25, 0.0, 0.0)),
    "rightHand": ("rightLowerArm", (-0.25, 0.0, 0.0)),
    "leftUpperLeg": ("hips", (0.1, -0.05, 0.0)),
    "leftLowerLeg": ("leftUpperLeg", (0.0, -0.4, 0.0)),
    "leftFoot": ("leftLowerLeg", (0.0, -0.4, 0.0)),
    "rightUpperLeg": ("hips", (-0.1, -0.05, 0.0)),
    "rightLowerLeg": ("rightUpperLeg", (0.0, -0.4, 0.0)),
    "rightFoot": ("rightLowerLeg", (0.0, -0.4, 0.0)),
}
FACE_MESH = "Face"


def _face(n_targets: int) -> tuple[np.ndarray, np.ndarray]:
    """A disc of ``n_targets + 1`` rim vertices around a centre, facing +Z: (positions, triangles)."""
    rim = n_targets + 1
    angles = np.linspace(0.0, 2.0 * np.pi, rim, endpoint=False)
    positions = np.zeros((rim + 1, 3), np.float32)
    positions[1:, 0] = 0.1 * np.cos(angles)
    positions[1:, 1] = 0.1 * np.sin(angles)
    triangles = np.array([(0, 1 + i, 1 + (i + 1) % rim) for i in range(rim)], np.uint16)
    return positions, triangles


def build_vrm(expressions: Sequence[str], name: str = "lipstream test avatar") -> bytes:
    """The GLB bytes of an avatar with one morph-target expression per name in ``expressions``."""
    targets = [*expressions, UNBOUND_TARGET]
    positions, triangles = _face(len(targets))
    blobs: list[bytes] = []
    views: list[dict[str, object]] = []
    accessors: list[dict[str, object]] = []

    def add(array: np.ndarray, accessor: dict[str, object], target: int) -> int:
        offset = sum(len(b) for b in blobs)
        data = array.tobytes()
        blobs.append(data + b"\0" * (-len(data) % 4))
        views.append({"buffer": 0, "byteOffset": offset, "byteLength": len(data), "target": target})
        accessors.append({"bufferView": len(views) - 1, **accessor})
        return len(accessors) - 1

    def vec3(array: np.ndarray) -> int:
        bounds = {"min": array.min(axis=0).tolist(), "max": array.max(axis=0).tolist()}
        return add(
            array,
            {"componentType": FLOAT, "count": len(array), "type": "VEC3", **bounds},
            ARRAY_BUFFER,
        )

    indices = add(
        triangles.reshape(-1),
        {"componentType": UNSIGNED_SHORT, "count": triangles.size, "type": "SCALAR"},
        ELEMENT_ARRAY_BUFFER,
    )
    position = vec3(positions)
    morphs = []
    for k in range(len(targets)):
        delta = np.zeros_like(positions)
        delta[1 + k, 2] = 0.02  # target k pushes rim vertex k forward
        morphs.append({"POSITION": vec3(delta)})

    bones = list(SKELETON)
    nodes: list[dict[str, object]] = [
        {"name": bone, "translation": list(SKELETON[bone][1])} for bone in bones
    ]
    for bone, (parent, _) in SKELETON.items():
        if parent is not None:
            siblings = nodes[bones.index(parent)].setdefault("children", [])
            assert isinstance(siblings, list)
            siblings.append(bones.index(bone))
    face_node = len(nodes)
    nodes.append({"name": FACE_MESH, "mesh": 0, "translation": [0.0, 0.05, 0.08]})
    head = nodes[bones.index("head")]
    head.setdefault("children", [])
    assert isinstance(head["children"], list)
    head["children"].append(face_node)

    binds = {
        expression: {
            "morphTargetBinds": [{"node": face_node, "index": k, "weight": 1.0}],
            "isBinary": False,
            "overrideBlink": "none",
            "overrideLookAt": "none",
            "overrideMouth": "none",
        }
        for k, expression in enumerate(expressions)
    }
    binary = b"".join(blobs)
    document = {
        "asset": {"version": "2.0", "generator": "lipstream tests"},
        "extensionsUsed": ["VRMC_vrm"],
        "scene": 0,
        "scenes": [{"nodes": [bones.index("hips")]}],
        "nodes": nodes,
        "meshes": [
            {
                "name": FACE_MESH,
                "primitives": [
                    {"attributes": {"POSITION": position}, "indices": indices, "targets": morphs}
                ],
                "weights": [0.0] * len(targets),
                "extras": {"targetNames": targets},
            }
        ],
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": len(binary)}],
        "extensions": {
            "VRMC_vrm": {
                "specVersion": "1.0",
                "meta": {
                    "name": name,
                    "authors": ["lipstream tests"],
                    "licenseUrl": VRM_LICENCE_URL,
                },
                "humanoid": {"humanBones": {bone: {"node": i} for i, bone in enumerate(bones)}},
                "expressions": {
                    "preset": {e: binds[e] for e in expressions if e in VRM1_PRESETS},
                    "custom": {e: binds[e] for e in expressions if e not in VRM1_PRESETS},
                },
            }
        },
    }
    return glb(document, binary)


def glb(document: dict[str, object], binary: bytes) -> bytes:
    """A GLB container of a glTF JSON document and its binary buffer."""
    text = json.dumps(document).encode()
    text += b" " * (-len(text) % 4)
    binary += b"\0" * (-len(binary) % 4)
    length = 12 + 8 + len(text) + 8 + len(binary)
    return (
        struct.pack("<III", GLB_MAGIC, 2, length)
        + struct.pack("<II", len(text), CHUNK_JSON)
        + text
        + struct.pack("<II", len(binary), CHUNK_BIN)
        + binary
    )
