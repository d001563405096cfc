"""The contract of a shading method, in three parts a method implements apart: its
numerics (:class:`Shading`), its settings in ``scene.prt`` (:class:`Settings`) and what the
benchmarks, the report and AUTO read of it (:class:`Bench`); a :class:`Method` record ties
them to the method's id.  This module imports no other module of the add-on, so the frame
state, the operators and the method packages may all import it without an import cycle.

A method turns the synced scene (:class:`..frame.state.FrameState`: world, objects, their
stored visibility) into pixels:

* ``Shading.shade(state, eye, view_dir)`` returns, for each ``state.objects`` entry, the
  per-corner linear radiance (C, 3) float32 drawn with Gouraud interpolation (``eye``:
  perspective camera position, or ``view_dir``: unit direction toward an orthographic
  camera).  A per-pixel GPU method overrides ``draw_objects`` instead: callables
  ``draw(view_projection)`` that draw each object into the bound framebuffer.
* ``Shading.derive(job)`` (optional, no bpy, in the precompute worker after the visibility
  is traced; may raise ``core.common.parallel.Cancelled`` when ``job.cancel_requested``)
  returns method data; ``store(scene, job, derived)`` (main thread, last in the commit)
  writes it to the .blend; ``sync(state)`` loads stored data into
  ``state.objects[i].data`` each time a frame state is built.
* ``Settings.scene_properties()`` returns ``{name: bpy.props.*Property(...)}`` added to
  ``scene.prt``; ``Settings.draw`` shows them.
* ``Bench.budget`` names the setting swept by the benchmarks/report as ``(property name,
  values)``; ``budget_between(lower, upper)`` gives a value strictly between two of them
  (AUTO bisects with it); ``stability_cases()`` the hard cases only this method has;
  ``last_choices()`` what the method chose per object for the newest frame (AUTO).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field


class Shading(ABC):
    """A method's numerics: precompute-time derivation and per-frame shading."""

    def draws_lamps(self, settings: dict) -> bool:
        """Whether ``shade``/``draw_objects`` draw Blender's point and spot lights
        (``state.lamps``) with these ``scene.prt`` settings; else the per-pixel lamp pass
        every method shares draws them."""
        return False

    def view_dependent(self, state) -> bool:
        """Whether the frame changes with the camera (glossy or layered materials)."""
        return False

    def shades_on_gpu(self, state) -> bool:
        """Whether ``shade``'s view-dependent work runs on a hardware GPU here (milliseconds:
        the viewport shades a moved camera at once, not in a worker thread)."""
        return False

    def sync(self, state):
        """Called at the end of FrameState.sync (load stored per-method data)."""

    @abstractmethod
    def shade(self, state, eye, view_dir):
        """Per-corner radiance (C, 3) float32 for each of ``state.objects`` (every method
        implements it; a subclass without it cannot be instantiated)."""

    def draw_objects(self, state, eye, view_dir):
        """Per-pixel drawing hook; None means: draw ``shade``'s per-corner radiance."""
        return None

    def derive(self, job):
        """Method data computed from ``job.objects[i].bits`` (precompute worker, no bpy)."""
        return None

    def store(self, scene, job, derived):
        """Write ``derived`` into the .blend (main thread, precompute commit)."""


class Settings:
    """A method's settings in ``scene.prt``; the default has none."""

    def scene_properties(self) -> dict:
        return {}

    def draw(self, layout, prt):
        for name in self.scene_properties():
            layout.prop(prt, name)


class Bench:
    """What the benchmarks, the report and AUTO read of a method; the default has no
    budget, no hard cases of its own and no per-object choices."""

    #: (scene.prt property, values swept by bench/report), or None.
    budget = None

    def budget_between(self, lower, upper):
        """A budget value strictly between ``lower`` and ``upper`` (two values of
        :attr:`budget`, ``lower`` the cheaper), cheaper than ``upper``; None when there
        is none (the default: AUTO then only tries the listed values)."""
        return None

    def stability_cases(self) -> list:
        """Hard cases of the stability table (``addon/benchmark/cases.py``) that only
        concern this method, in the form of ``cases.BASE_CASES``; the table names them
        ``"<name> [<method id>]"``."""
        return []

    def last_choices(self) -> list:
        """What the method chose per object for the newest frame (AUTO: dicts with
        ``object``, ``method``, ``setting``, ``value``, ``choice``, ``error``, ``seconds``,
        ``reason``), shown by the panel and the report; [] for a fixed method."""
        return []


@dataclass(frozen=True)
class Method:
    """A registered method: its id in ``scene.prt.method``, label, description and parts."""

    id: str
    label: str
    description: str
    shading: Shading
    settings: Settings = field(default_factory=Settings)
    bench: Bench = field(default_factory=Bench)

    @property
    def derives(self) -> bool:
        """Whether the precompute must keep the traced bits for :meth:`Shading.derive`."""
        return type(self.shading).derive is not Shading.derive


def glossy_or_layered(state) -> bool:
    """Whether any synced material has a glossy lobe or Principled layering (its
    radiance then depends on the view) -- the view dependence of per-vertex methods
    that shade the full core material."""
    return any(not m.is_diffuse_only or m.fresnel == "DIELECTRIC"
               for st in state.objects for m in st.materials)
