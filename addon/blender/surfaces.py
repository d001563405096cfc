"""The surfaces a render shows, one :class:`Surface` each: every evaluated geometry object,
and every instance an instancer places (collection instances, particle systems that render
objects or collections, geometry-nodes instances: ``depsgraph.object_instances``).

An instance is drawn, traced and stored like an object: its mesh is its source's, placed by
the instance's world matrix (the source's object-space arrays are exported once and shared
by every instance of it; only the positions and normals are transformed copies, since
Embree traces world-space triangles); its record and blobs are kept on its instancer under
its persistent id (``storage.InstanceRecord``), so they are saved, duplicated and removed
with the instancer, and an instance keeps its data while its instancer holds it in place.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from types import SimpleNamespace

import numpy as np

from ...core.scene import mesh as core_mesh
from ...core.scene.mesh import MeshArrays
from . import scene_export, storage

#: the padding of an unused level of ``persistent_id``
_UNUSED = 2**31 - 1


@dataclass(eq=False)
class Surface:
    """One drawn surface: ``name`` (the object's, or ``Instancer#key`` for an instance:
    storage.instance_name), ``ob`` the evaluated object whose mesh, materials and textures
    it shows (a :class:`GeometrySource` for geometry instanced without an object),
    ``matrix`` its 4x4 world matrix, ``owner`` where its record and blobs live (the
    original object or a storage.InstanceRecord)."""

    name: str
    ob: object
    matrix: np.ndarray
    owner: object
    instance: bool = False

    @property
    def hidden(self) -> bool:
        """Hidden from renders (the object, or the instancer of an instance)."""
        return bool(self.owner.hide_render)


def note_group(surface: Surface) -> str | None:
    """What ``surface``'s notes are grouped under (core.pipeline.frame_status.grouped_notes):
    an instance's source, the object or geometry its instances show (a scatter made of a
    thousand instancers is one source); None for an object."""
    return surface.ob.name if surface.instance else None


class GeometrySource:
    """Geometry instanced without an object (geometry nodes' Instance on Points of a mesh):
    the evaluated mesh its instances share, standing in for an evaluated object where the
    export reads one (``to_mesh``, ``material_slots``: the mesh's own materials)."""

    def __init__(self, mesh, instancer_name: str):
        self.mesh = mesh
        self.name = f"{instancer_name} (instanced geometry)"
        self.material_slots = [SimpleNamespace(material=m) for m in mesh.materials]

    def to_mesh(self):
        return self.mesh

    def to_mesh_clear(self):
        pass


def instance_key(persistent_id) -> str:
    """An instance's key on its instancer: its persistent id's used levels (``3``, ``0.12``)."""
    return ".".join(str(int(i)) for i in persistent_id if int(i) != _UNUSED)


def scene_surfaces(depsgraph, hidden_from_render: list | None = None) -> list:
    """Every :class:`Surface` the render shows, objects then instances, each in a stable
    order (names; an instancer's instances by key).

    A render depsgraph holds what the render shows; a viewport depsgraph what the viewport
    shows, less what is hidden from renders (``hide_render``, the object's or its
    instancer's): never traced, so the precompute and F12 agree on what casts shadows.  When
    ``hidden_from_render`` is given (the viewport, which shows them), such surfaces are
    appended to it instead of being dropped.  Curves, text, surfaces and metaballs come as
    their own object plus a mesh instance of themselves; the object is used.
    """
    objects, instances = [], []
    sources = {}
    for inst in depsgraph.object_instances:
        ob = inst.object
        if ob.type not in scene_export.GEOMETRY_TYPES:
            continue
        if not inst.is_instance:
            if not inst.show_self:           # a particle emitter not shown in renders
                continue
            s = Surface(ob.original.name, ob, np.array(ob.matrix_world, np.float64),
                        ob.original)
            objects.append(s)
            continue
        parent = inst.parent
        if parent is None:
            continue
        if ob.original == parent.original:
            if parent.original.type != "MESH":
                continue                     # a curve/text object's own evaluated geometry
            # geometry instanced without an object: its evaluated mesh outlives the loop
            # (inst.object is a temporary the iterator reuses)
            ptr = ob.data.as_pointer()
            if ptr not in sources:
                sources[ptr] = GeometrySource(ob.data, parent.original.name)
            source = sources[ptr]
        else:
            source = ob.original.evaluated_get(depsgraph)
        record = storage.InstanceRecord(parent.original, instance_key(inst.persistent_id))
        instances.append(Surface(record.name, source, np.array(inst.matrix_world, np.float64),
                                 record, instance=True))
    objects.sort(key=lambda s: s.name)
    instances.sort(key=lambda s: (s.owner.instancer.name,
                                  tuple(int(k) for k in s.owner.key.split(".") if k)))
    found = []
    for s in objects + instances:
        if s.hidden:
            if hidden_from_render is not None:
                hidden_from_render.append(s)
            continue
        found.append(s)
    return found


class SharedArrays:
    """The object-space arrays of each instanced source, exported once per pass and shared
    by its instances (:func:`arrays`)."""

    def __init__(self):
        self.local = {}
        self._fingerprints = {}
        self._points = {}

    @staticmethod
    def _key(surface: Surface):
        return id(surface.ob) if isinstance(surface.ob, GeometrySource) else surface.ob.name_full

    def arrays(self, surface: Surface) -> MeshArrays:
        """World-space arrays of ``surface``: an object's as scene_export.mesh_arrays; an
        instance's are its source's with transformed positions and normals and the index
        arrays (corners, triangles, materials) shared with every other instance of it."""
        if not surface.instance:
            return scene_export.mesh_arrays(surface.ob)
        key = self._key(surface)
        if key not in self.local:
            self.local[key] = scene_export.mesh_arrays(surface.ob, np.eye(4))
        return placed(self.local[key], surface.matrix)

    def shared_points(self, surface: Surface, points):
        """``points`` (core.scene.mesh.ShadingPoints of an instance) holding the index arrays
        (corners' points, points' slots) of the first instance of its source where they are
        equal, as they are unless a turn regroups near-equal normals: one copy per source."""
        if not surface.instance:
            return points
        key = self._key(surface)
        first = self._points.get(key)
        if first is None:
            for a in (points.point_of_corner, points.materials):
                a.flags.writeable = False           # shared by instances from here on
            self._points[key] = points
            return points
        if (np.array_equal(first.point_of_corner, points.point_of_corner)
                and np.array_equal(first.materials, points.materials)):
            return replace(points, point_of_corner=first.point_of_corner,
                           materials=first.materials)
        return points

    def source(self, surface: Surface, arrays: MeshArrays):
        """An instance's source as the lights pass shares it (addon/gpu/lights.py): the
        core.scene.mesh.fingerprint of its object-space arrays and those arrays, when
        ``arrays`` (what sync made of :meth:`arrays`) still index its corners (not re-sided);
        None for an object."""
        got = self.local_source(surface)
        if got is None or not np.may_share_memory(got[1].triangles, arrays.triangles):
            return None
        return got

    def local_source(self, surface: Surface):
        """``(fingerprint, object-space arrays)`` of an instance's source, whatever sides
        the frame gives the instance (its shadow-casting triangles are the same: the bounce's
        shadow rays test it there, core.scene.placed_occluders); None for an object."""
        if not surface.instance:
            return None
        key = self._key(surface)
        local = self.local.get(key)
        if local is None:
            return None
        if key not in self._fingerprints:
            self._fingerprints[key] = core_mesh.fingerprint(local)
        return self._fingerprints[key], local

    def nbytes(self) -> int:
        """Bytes of the shared object-space arrays."""
        return sum(a.positions.nbytes + a.corner_verts.nbytes + a.corner_normals.nbytes
                   + a.triangles.nbytes + a.corner_materials.nbytes
                   for a in self.local.values())


def placed(local: MeshArrays, matrix) -> core_mesh.PlacedArrays:
    """``local`` (object space) placed by ``matrix``: the same index arrays, and positions
    and corner normals placed (the normals repaired, as sync and the precompute repair an
    object's) each time they are read: core.scene.mesh.PlacedArrays."""
    M = np.asarray(matrix, np.float64)
    none = np.zeros((0, 3))

    def positions():
        # element by element, not a BLAS product (whose kernels may split rows differently
        # from one call to the next): every read gives the same bits, as the passes' depth
        # test EQUAL needs of positions drawn from two reads
        p = local.positions
        return p[:, :1] * M[:3, 0] + p[:, 1:2] * M[:3, 1] + p[:, 2:3] * M[:3, 2] + M[:3, 3]
    return core_mesh.PlacedArrays(
        local, positions, lambda: scene_export.transformed(none, local.corner_normals, M)[1])
