"""core.pipeline.frame_status: which status an object's stored visibility gives it
(stored_status, its truth table from the definition) and what a frame says about the
objects drawn without their stored data (SyncNotes: which list each status goes to, the
messages in their order, one per kind, naming the objects), and which viewport updates
change the World alone (world_only).  No bpy."""

from __future__ import annotations

import itertools

import pytest

from prt_relight.core.pipeline import frame_status
from prt_relight.core.pipeline.frame_status import SyncNotes, stored_status


@pytest.mark.parametrize("found, dynamic, same", list(itertools.product([False, True], repeat=3)))
def test_stored_status_truth_table(found, dynamic, same):
    """No rows at the frame's points: stale (whatever else); shadow fields: the motion
    decides (dynamic); else the fingerprint: ok when unchanged, stale when edited."""
    want = "stale" if not found else "dynamic" if dynamic else "ok" if same else "stale"
    assert stored_status(found, dynamic, same) == want


def test_statuses_are_the_four_a_frame_draws():
    assert frame_status.STATUSES == ("ok", "stale", "missing", "unshadowed")
    assert stored_status(True, False, True) in frame_status.STATUSES


def test_add_sends_each_status_to_its_list():
    notes = SyncNotes()
    for name, status in [("a", "ok"), ("b", "stale"), ("c", "missing"), ("d", "unshadowed"),
                         ("e", "dynamic"), ("f", "posed")]:
        notes.add(name, status)
    notes.add("g", "missing", legacy=True)            # data of an earlier layout
    notes.add("h", "stale", legacy=True)              # legacy only matters when missing
    assert notes.missing == ["c"] and notes.older == ["g"]
    assert notes.stale == ["b", "h"] and notes.unshadowed == ["d"]
    assert notes.unreadable == [] and notes.earlier == []


def test_no_note_no_message():
    assert SyncNotes().messages() == []
    ok = SyncNotes()
    ok.add("a", "ok")
    ok.add("b", "dynamic")
    assert ok.messages() == []


def test_a_scatter_of_a_thousand_is_a_line_that_names_some_and_counts_the_rest():
    notes = SyncNotes(unreadable=[f"'I{i}#0': damaged" for i in range(1000)])
    for i in range(1000):
        notes.add(f"I{i}#0", "missing")
    out = notes.messages()
    assert out[0].startswith("Not precomputed (drawn without shadows): I0#0, I1#0")
    assert out[0].endswith(f"I{frame_status.LISTED - 1}#0 and {1000 - frame_status.LISTED} more")
    damaged = [m for m in out if "damaged" in m]
    assert len(damaged) == frame_status.LISTED
    assert f"{1000 - frame_status.LISTED} more objects cannot be read" in out[-1]
    assert len(out) == frame_status.LISTED + 2 and max(map(len, out)) < 200
    assert frame_status.listing(["a", "b"]) == "a, b"


def test_messages_name_their_objects_most_pressing_first():
    notes = SyncNotes(unreadable=["'Cube': the stored data is damaged"])
    notes.add("Grid", "missing")
    notes.add("Ball", "missing")
    notes.add("Old", "missing", legacy=True)
    notes.add("Hidden", "unshadowed")
    notes.add("Suzanne", "stale")
    out = notes.messages()
    assert len(out) == 5
    kinds = ["Not precomputed", "earlier prt_relight", "damaged", "Hidden from renders",
             "Changed since precompute"]
    for message, kind in zip(out, kinds):
        assert kind in message, (kind, message)
    assert out[0].endswith(": Grid, Ball") and "drawn without shadows" in out[0]
    assert out[1].endswith(": Old") and "press Precompute" in out[1]
    assert out[2] == "'Cube': the stored data is damaged (drawn without shadows)"
    assert out[3].endswith(": Hidden") and "cast none" in out[3]
    assert out[4].endswith(": Suzanne") and "stale" in out[4]


@pytest.mark.parametrize("stale, earlier, removed, want", [
    (True, True, True, "Changed since precompute"),
    (False, True, True, "earlier run than the others"),
    (False, False, True, "removed or hidden from renders since the precompute"),
    (False, False, False, None),
])
def test_one_note_about_stale_shadows_the_most_pressing(stale, earlier, removed, want):
    """Changed objects, objects of an earlier run and objects removed since the precompute
    all make shadows stale: one message says so, the most specific one."""
    notes = SyncNotes(earlier=["Grid"] if earlier else [])
    if stale:
        notes.add("Suzanne", "stale")
    out = notes.messages(removed_since=removed)
    if want is None:
        assert out == []
    else:
        assert len(out) == 1 and want in out[0]
        assert "press Precompute" in out[0]
        if earlier and not stale:
            assert out[0].endswith(": Grid")


def test_grouped_notes_give_one_line_per_instanced_source():
    notes = [("'Cube' is too coarse", None), ("'Herd#0' is too coarse", "Cow"),
             ("'Pen#1' is too coarse", "Cow"), ("'Pen#3' is too coarse", "Pig")]
    got = frame_status.grouped_notes(notes)
    assert got[0] == "'Cube' is too coarse" and "'Pen#3' is too coarse" in got
    cows = [m for m in got if "Cow" in m]
    assert len(got) == 3 and len(cows) == 1
    assert cows[0].startswith("2 instances of 'Cow'") and "'Herd#0'" in cows[0]
    assert frame_status.grouped_notes([]) == []


def test_world_only_updates():
    """An HDRI turn names the World and its node tree: the objects hold; anything else
    (a scene setting, an object, a material's tree, a node group) or nothing does not."""
    assert frame_status.world_only([("World", True), ("ShaderNodeTree", True)])
    assert frame_status.world_only([("World", True)])
    assert not frame_status.world_only([])
    assert not frame_status.world_only([("World", True), ("Scene", False)])
    assert not frame_status.world_only([("World", True), ("ShaderNodeTree", False)])
    assert not frame_status.world_only([("Object", False)])
    assert not frame_status.world_only([("Image", True)])
