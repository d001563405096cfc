"""Precompute results stored in the .blend, on the objects that own them.

Every result is a named blob (:mod:`..core.common.codec`: versioned, zlib-compressed typed
arrays and JSON meta) in the Object datablock's ID property group ``prt_store``::

    ob["prt_store"][name] = {"blob": bytes, "uid": str, "run": str}

``uid`` is new for every put (the key decoded data is cached under), ``run`` the
precompute the blob belongs to (``ob.prt.precompute_id``; a blob of another run is
ignored).  The blobs live on the datablock, so Blender's own rename, duplicate (linked
or full), delete, undo, save, append and link carry or drop them; nothing is looked up
by object name.  ``ob.prt`` stays the record of the precompute (resolution, point
count, geometry fingerprint, run, tessellation note).

An instance (a collection instance, a particle, a geometry-nodes instance) has no
datablock of its own: its record and blobs live on its instancer, keyed by the instance's
persistent id (:class:`InstanceRecord`), ``instancer["prt_instances"][key] = {"record":
{...}, "prt_store": {...}}``; so they too are saved, duplicated and deleted with the
instancer.  :func:`owner` finds what a name from a precompute or a frame stands for.

Results of the earlier layout (packed float images, ``prt_rsl_*`` properties) are not
read: such objects are reported as needing a precompute, and a precompute or Clear
removes that data.
"""

import uuid

import bpy

from ...core.common import codec
from ..frame import keys
from . import attributes
from ...core.store.layouts import BOUNCE, SHADOW_FIELD, VISIBILITY  # noqa: F401  (the blob names)

STORE = "prt_store"
#: the instances' records and blobs on their instancer (:class:`InstanceRecord`)
INSTANCES = "prt_instances"
#: an instance's name: its instancer's name, this, its key (``Herd#3``, ``Field#0.12``)
INSTANCE_SEP = "#"
#: blob that cannot be read (damaged, or written by a newer prt_relight)
Unreadable = codec.FormatError
#: images of the earlier layout: tagged with this ID property, or named with a prefix
LEGACY_TAG = "prt_relight"
LEGACY_PREFIXES = ("PRT Visibility ", "PRT Blocks ", "PRT RSL ", "PRT SSDF ")


# ------------------------------------------------------------------ blobs (no bpy)

def pack(arrays: dict, meta: dict | None = None) -> bytes:
    """A blob of typed arrays and meta (any thread): :func:`core.common.codec.pack`."""
    return codec.pack(arrays, meta)


# ------------------------------------------------------------------ per object

def _entry(ob, name):
    store = ob.get(STORE) if ob is not None else None
    return store.get(name) if hasattr(store, "get") else None


def key(ob, name: str):
    """Cheap identity of ``ob``'s blob ``name`` (a new one per put), None when it has
    none of its current precompute.  An entry this version cannot make sense of gets a
    key too, so that :func:`get` reports it."""
    entry = _entry(ob, name)
    if entry is None:
        return None
    # membership only: reading entry["blob"] would copy the whole blob
    if not hasattr(entry, "keys") or "blob" not in entry or "uid" not in entry:
        return ("unreadable", name)
    if entry.get("run") != ob.prt.precompute_id:
        return None
    return entry.get("uid")


def has(ob, name: str) -> bool:
    return key(ob, name) is not None


def get(ob, name: str):
    """``(arrays, meta)`` of ``ob``'s blob ``name`` of its current precompute, or None;
    :data:`Unreadable` (its message says why) when it cannot be read."""
    data = blob(ob, name)
    return None if data is None else codec.unpack(data)


def blob(ob, name: str) -> bytes | None:
    """The packed bytes of ``ob``'s blob ``name`` of its current precompute (main thread;
    :func:`get` unpacks them), or None; :data:`Unreadable` when it is no blob."""
    if key(ob, name) is None:
        return None
    entry = _entry(ob, name)
    data = entry.get("blob") if hasattr(entry, "get") else None
    if not isinstance(data, bytes):
        raise codec.NewerFormatError("stored in a layout this prt_relight does not know")
    return data


def load(ob, name: str, cache, convert=None, note=None):
    """``convert(arrays, meta)`` of ``ob``'s blob ``name`` (``(arrays, meta)`` without
    ``convert``), made once per blob and kept in ``cache`` (a :func:`.keys.cache`: its
    bound applies).  None when there is no blob of the current precompute, or when it is
    unreadable: then ``note`` (a callable) is told why."""
    k = key(ob, name)
    if k is None:
        return None

    def read():
        arrays, meta = get(ob, name)
        return (arrays, meta) if convert is None else convert(arrays, meta)

    try:
        return keys.held(cache, k, (), read)
    except Unreadable as exc:
        if note is not None:
            note(f"'{ob.name}': {exc}: precompute again")
        return None


def stored_bytes(ob, name: str | None = None) -> int:
    """Bytes of ``ob``'s blob ``name`` (of every blob without ``name``)."""
    store = ob.get(STORE)
    if not hasattr(store, "keys"):
        return 0
    names = [name] if name is not None else list(store.keys())
    blobs = (e.get("blob") for e in (store.get(n) for n in names) if hasattr(e, "get"))
    return sum(len(b) for b in blobs if isinstance(b, bytes))


def put(ob, name: str, blob: bytes):
    """Store ``blob`` as ``name`` of ``ob``'s current precompute (main thread)."""
    if not isinstance(blob, bytes):
        raise TypeError("put() takes a blob made by storage.pack()")
    if not hasattr(ob.get(STORE), "keys"):
        ob[STORE] = {}
    ob[STORE][name] = {"blob": blob, "uid": uuid.uuid4().hex, "run": ob.prt.precompute_id}


def replace_all(ob, blobs: dict):
    """``ob``'s blobs become ``blobs`` (name -> blob) of its current precompute: what an
    earlier precompute stored for it (any method, any layout) goes."""
    run = ob.prt.precompute_id
    ob[STORE] = {name: {"blob": blob, "uid": uuid.uuid4().hex, "run": run}
                 for name, blob in blobs.items()}
    for k in [k for k in ob.keys() if k.startswith("prt_") and k not in (STORE, INSTANCES)]:
        del ob[k]


def delete(ob, name: str):
    store = ob.get(STORE)
    if hasattr(store, "keys") and name in store:
        del store[name]


def clear_object(ob) -> bool:
    """Remove everything stored on ``ob`` (blobs, ``prt_*`` properties, the precompute
    record); True when it had any."""
    keys = [k for k in ob.keys() if k.startswith("prt_")]
    had = bool(keys) or bool(ob.prt.point_count) or bool(ob.prt.precompute_id)
    for k in keys:
        del ob[k]
    ob.property_unset("prt")            # the record, and an earlier layout's image link
    return had


def legacy(ob) -> bool:
    """True when ``ob`` was precomputed but holds no visibility in this layout (stored
    by an earlier prt_relight)."""
    return bool(ob.prt.point_count) and _entry(ob, VISIBILITY) is None


def remove_legacy() -> int:
    """Remove the earlier layout's images and object properties (this version does not
    read them); returns how many images went."""
    images = [i for i in bpy.data.images
              if i.library is None and (i.get(LEGACY_TAG) or i.name.startswith(LEGACY_PREFIXES))]
    for img in images:
        bpy.data.images.remove(img)
    for ob in bpy.data.objects:
        if ob.library is None:
            for k in [k for k in ob.keys() if k.startswith("prt_rsl_")]:
                del ob[k]
    return len(images)


def clear_all() -> int:
    """Remove everything the add-on stored in the .blend: every object's blobs, ``prt_*``
    properties and record (also of objects no scene shows), the earlier layout's images,
    the scenes' precompute record, the meshes' PRT attributes (:mod:`.attributes`).
    Objects linked from a library keep theirs (that file holds it).  Returns how many
    objects had data."""
    count = sum(clear_object(ob) for ob in bpy.data.objects if ob.library is None)
    attributes.remove_all(bpy.data)
    remove_legacy()
    for scene in bpy.data.scenes:
        prt = getattr(scene, "prt", None)
        if prt is not None and scene.library is None:
            prt.precomputed_resolution = 0
            prt.scene_fingerprint = ""
            prt.precompute_id = ""
            prt.precomputed_objects = 0
            prt.last_report = ""
            prt.auto_choice = ""
    return count


# ------------------------------------------------------------------ per instance

#: an instance's record and its default values (the fields of ``object.prt`` a precompute
#: writes and a frame reads)
_RECORD_FIELDS = {"resolution": 0, "point_count": 0, "fingerprint": "", "precompute_id": "",
                  "coarse_warning": "", "back_sides": False}


def instance_name(instancer_name: str, key: str) -> str:
    return f"{instancer_name}{INSTANCE_SEP}{key}"


class _InstanceFields:
    """``object.prt``'s precompute record for one instance, read from and written to its
    group on the instancer; ``dynamic`` is its instancer's flag (the instances of a dynamic
    instancer carry shadow fields and follow it with live shadows)."""

    def __init__(self, record):
        object.__setattr__(self, "_record", record)

    def __getattr__(self, name):
        if name == "dynamic":
            return bool(self._record.instancer.prt.dynamic)
        if name not in _RECORD_FIELDS:
            raise AttributeError(name)
        group = self._record.group()
        got = group.get("record", {}).get(name) if group is not None else None
        return _RECORD_FIELDS[name] if got is None else type(_RECORD_FIELDS[name])(got)

    def __setattr__(self, name, value):
        if name not in _RECORD_FIELDS:
            raise AttributeError(f"an instance's record has no '{name}'")
        group = self._record.group(create=True)
        if "record" not in group:
            group["record"] = {}
        group["record"][name] = value


class InstanceRecord:
    """Where one instance's precompute record and blobs are kept: the group ``key`` (its
    persistent id) of its instancer's ``prt_instances``.  Stands in for an object wherever
    this module and the methods store or read per object: ``.prt``, ``.name``,
    ``.hide_render``, ``.library`` and the ID-property access (``get``, ``[]``, ``keys``)."""

    def __init__(self, instancer, key: str):
        self.instancer = instancer
        self.key = key
        self.name = instance_name(instancer.name, key)
        self.prt = _InstanceFields(self)

    def group(self, create: bool = False):
        groups = self.instancer.get(INSTANCES)
        if not hasattr(groups, "keys"):
            if not create:
                return None
            self.instancer[INSTANCES] = {}
            groups = self.instancer[INSTANCES]
        if self.key not in groups:
            if not create:
                return None
            groups[self.key] = {}
        return groups[self.key]

    @property
    def original(self):
        return self

    @property
    def hide_render(self) -> bool:
        return bool(self.instancer.hide_render)

    @property
    def library(self):
        return self.instancer.library

    def get(self, name, default=None):
        group = self.group()
        return default if group is None else group.get(name, default)

    def keys(self):
        group = self.group()
        return [] if group is None else list(group.keys())

    def __contains__(self, name):
        return name in self.keys()

    def __getitem__(self, name):
        group = self.group()
        if group is None:
            raise KeyError(name)
        return group[name]

    def __setitem__(self, name, value):
        self.group(create=True)[name] = value

    def __delitem__(self, name):
        del self.group()[name]

    def property_unset(self, name):
        group = self.group()
        if group is not None and "record" in group:
            del group["record"]


def owner(name: str):
    """The object named ``name``, or the :class:`InstanceRecord` an instance's name
    (:func:`instance_name`) stands for; None when neither exists."""
    ob = bpy.data.objects.get(name)
    if ob is not None:
        return ob
    instancer, sep, key = name.rpartition(INSTANCE_SEP)
    ob = bpy.data.objects.get(instancer) if sep else None
    return None if ob is None else InstanceRecord(ob, key)


def instance_records(instancer) -> list:
    """The :class:`InstanceRecord` of every instance ``instancer`` stores."""
    groups = instancer.get(INSTANCES)
    return [InstanceRecord(instancer, k) for k in groups.keys()] if hasattr(groups, "keys") else []


def keep_instances(instancer, keys):
    """Drop the records of ``instancer``'s instances not in ``keys`` (a precompute no
    longer found them)."""
    groups = instancer.get(INSTANCES)
    if hasattr(groups, "keys"):
        for k in [k for k in groups.keys() if k not in keys]:
            del groups[k]
