"""The precompute's per-point results as mesh attributes an artist can use: ``PRT AO`` (the
cosine-weighted visible fraction of the sky), ``PRT Bent Normal`` (object space) and the SH
transfer vector ``PRT SH 0`` ... of the order ``scene.prt.attribute_sh_order`` (Sloan et al.
2002, in the World's basis at the precompute), written on the Face Corner domain at
Precompute; on demand (``prt.frame_attributes``) the current frame's ``PRT Irradiance`` and
``PRT Radiance``.  They live in the mesh like any attribute (the Spreadsheet, the Attribute
node of Cycles and EEVEE, Geometry Nodes, glTF's custom attributes; undo, save, duplicate,
append and link keep them) and ``prt.clear`` removes them.

An object's shading points are those of its evaluated mesh; they are written on its mesh
when the two have the same corners (no modifier adds or removes any), else not, with a
note.  Objects sharing a mesh share its attributes: the last written is kept.
"""

from __future__ import annotations

import numpy as np

from ...core.methods.reference import shading as reference
from ...core.methods.sh import harmonics
from ...core.sphere import directions

#: every attribute the add-on writes starts with this
PREFIX = "PRT "
AO, BENT, SH = "PRT AO", "PRT Bent Normal", "PRT SH "
IRRADIANCE, RADIANCE = "PRT Irradiance", "PRT Radiance"


def mesh_for(ob, corners: int, note=None):
    """``ob``'s mesh when its corners are the evaluated mesh's ``corners``, else None
    (``note`` told why)."""
    mesh = getattr(ob, "data", None)
    if mesh is None or ob.type != "MESH" or mesh.library is not None:
        return None
    if len(mesh.loops) != corners:
        if note is not None:
            note(f"'{ob.name}': its modifiers change its corners ({len(mesh.loops)} → "
                 f"{corners}); no PRT attributes written (apply them to have them)")
        return None
    return mesh


def write(mesh, name: str, values: np.ndarray, data_type: str):
    """Write per-corner ``values`` as the Face Corner attribute ``name`` (made anew)."""
    old = mesh.attributes.get(name)
    if old is not None:
        mesh.attributes.remove(old)
    attr = mesh.attributes.new(name, data_type, "CORNER")
    field = "value" if data_type == "FLOAT" else ("color" if data_type == "FLOAT_COLOR"
                                                  else "vector")
    flat = np.ascontiguousarray(values, dtype=np.float32).reshape(-1)
    attr.data.foreach_set(field, flat)
    return attr


def precompute_values(bits, normals, resolution: int, sh_order: int) -> dict:
    """Per shading point: AO (P,), bent normal (P, 3) in world space and the SH transfer
    (P, order²) or None."""
    cube = directions.cubemap(resolution)
    return dict(ao=reference.sky_visibility(bits, normals, cube),
                bent=reference.bent_normals(bits, normals, cube),
                sh=harmonics.transfer(bits, normals, cube, sh_order) if sh_order else None)


def write_precompute(ob, arrays, points, values: dict, note=None) -> bool:
    """Write :func:`precompute_values` of an object's points on its mesh's corners (the
    front corners of a two-sided one); False when its mesh cannot take them."""
    corners = arrays.front_corners
    mesh = mesh_for(ob, corners, note)
    if mesh is None:
        return False
    for old in [a.name for a in mesh.attributes if a.name in (AO, BENT)
                or a.name.startswith(SH)]:    # an earlier precompute's (another SH order)
        mesh.attributes.remove(mesh.attributes[old])
    of = points.point_of_corner[:corners]
    write(mesh, AO, values["ao"][of], "FLOAT")
    # object space: the bent normal turns with the object as a normal does
    M = np.array(ob.matrix_world, dtype=np.float64)[:3, :3]
    bent = values["bent"][of].astype(np.float64) @ M
    bent /= np.maximum(np.linalg.norm(bent, axis=1, keepdims=True), 1e-30)
    write(mesh, BENT, bent, "FLOAT_VECTOR")
    if values["sh"] is not None:
        for k in range(values["sh"].shape[1]):
            write(mesh, f"{SH}{k}", values["sh"][of, k], "FLOAT")
    mesh.update()
    return True


def remove(mesh) -> int:
    """Remove every PRT attribute of ``mesh``; how many went."""
    names = [a.name for a in mesh.attributes if a.name.startswith(PREFIX)]
    for name in names:
        mesh.attributes.remove(mesh.attributes[name])
    return len(names)


def remove_all(bpy_data) -> int:
    """Remove the PRT attributes of every local mesh; how many meshes had any."""
    return sum(remove(m) > 0 for m in bpy_data.meshes if m.library is None)
