"""What a frame says about each object's stored precompute: whether it is drawn with its
stored visibility, stale, missing or unshadowed, and the messages the panels and the
render log show for them, and which updates leave the objects as they were (the policy of
``addon/frame/state.py``'s sync, bpy-free)."""

from __future__ import annotations

from dataclasses import dataclass, field

#: how an object is drawn: with its stored visibility ("ok"), with its old data after an
#: edit that kept its topology ("stale"), without shadows ("missing": never precomputed,
#: unreadable or older), unshadowed and casting none ("unshadowed": hidden from renders)
STATUSES = ("ok", "stale", "missing", "unshadowed")


def stored_status(bits_found: bool, dynamic: bool, fingerprint_same: bool) -> str:
    """The status of an object whose stored visibility was read at the frame's resolution:
    ``"stale"`` when its shading points no longer match (``bits_found`` false) or its
    geometry changed (same topology: the old data stays correctly indexed), ``"dynamic"``
    when it has shadow fields (its motion decides, ``addon.frame.dynamic.check``), else
    ``"ok"``."""
    if not bits_found:
        return "stale"
    if dynamic:
        return "dynamic"
    return "ok" if fingerprint_same else "stale"


def world_only(updates) -> bool:
    """Whether a viewport update changed the World alone (its node values: an HDRI turned,
    its strength dragged), so the objects, lamps and method data of the last sync still
    hold.  ``updates``: per updated ID, ``(kind, of_world)`` -- its type name ("World",
    "ShaderNodeTree", "Object", ...) and whether it is the scene's World or the World's own
    node tree.  Anything else (a scene setting, an object, a material, a node group the
    World uses, an image) is not; nor is an update that names nothing."""
    updates = list(updates)
    return bool(updates) and all(of_world and kind in ("World", "ShaderNodeTree")
                                 for kind, of_world in updates)


#: how many names a note lists before it counts the rest (a scatter of a thousand
#: instances is one readable line, not seven kilobytes of names)
LISTED = 8


def listing(names) -> str:
    """``names`` joined for a note: the first :data:`LISTED` and how many more."""
    names = list(names)
    shown = ", ".join(names[:LISTED])
    return shown if len(names) <= LISTED else f"{shown} and {len(names) - LISTED} more"


@dataclass
class SyncNotes:
    """Object names per kind of note, gathered while a frame state is synced."""

    missing: list = field(default_factory=list)
    older: list = field(default_factory=list)
    unreadable: list = field(default_factory=list)      # reasons, one per blob
    unshadowed: list = field(default_factory=list)
    stale: list = field(default_factory=list)
    earlier: list = field(default_factory=list)

    def add(self, name: str, status: str, legacy: bool = False):
        """Note ``name`` drawn as ``status``; a missing object with data of an earlier
        layout (``legacy``) is noted as older instead."""
        if status == "missing" and legacy:
            self.older.append(name)
        elif status in ("stale", "missing", "unshadowed"):
            getattr(self, status).append(name)

    def messages(self, removed_since: bool = False) -> list[str]:
        """The warnings, most pressing first; ``removed_since``: the scene traces fewer
        objects of the newest precompute than it had (shadows of removed objects stay)."""
        out = []
        if self.missing:
            out.append("Not precomputed (drawn without shadows): " + listing(self.missing))
        if self.older:
            out.append("Stored by an earlier prt_relight, which this version does not read "
                       "(drawn without shadows, press Precompute): " + listing(self.older))
        out += [w + " (drawn without shadows)" for w in self.unreadable[:LISTED]]
        if len(self.unreadable) > LISTED:
            out.append(f"{len(self.unreadable) - LISTED} more objects cannot be read (drawn "
                       "without shadows, precompute again)")
        if self.unshadowed:
            out.append("Hidden from renders (drawn without shadows, cast none): "
                       + listing(self.unshadowed))
        if self.stale:
            out.append("Changed since precompute (stale, press Precompute): "
                       + listing(self.stale))
        elif self.earlier:
            out.append("Precomputed in an earlier run than the others (their shadows on each "
                       "other may be stale, press Precompute): " + listing(self.earlier))
        elif removed_since:
            out.append("Objects were removed or hidden from renders since the precompute: "
                       "their shadows are stale, press Precompute")
        return out


def grouped_notes(notes) -> list[str]:
    """Per-surface notes ``(message, group)`` as the panels show them: an object's
    (``group`` None) as it is, the notes of the instances of one source (``group`` its
    name) as one line that counts them and quotes the first, so a scatter of a thousand
    instances gives one line, not a thousand, however many instancers place them."""
    out, groups = [], {}
    for message, group in notes:
        if group is None:
            out.append(message)
        else:
            groups.setdefault(group, []).append(message)
    for group, messages in groups.items():
        out.append(messages[0] if len(messages) == 1 else
                   f"{len(messages)} instances of '{group}' have notes, the first: "
                   + messages[0])
    return out
