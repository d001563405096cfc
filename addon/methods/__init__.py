"""Shading methods: one module each, registered here.

A method turns the synced scene (:class:`..runtime.FrameState`: world, objects,
their stored visibility) into pixels.  Each module defines a :class:`Method`
subclass and adds an instance to :data:`REGISTRY` with :func:`register`; the
``scene.prt.method`` enum, its settings, the panels and the benchmarks are built
from the registry, so adding a method touches no other glue but one import line in
:mod:`.catalog` (which loads the method modules in their UI order).  This module is
the contract alone: it imports no other module of the add-on, so the frame state, the
operators and the method modules may all import it without an import cycle.

The contract of a method:

* ``shade(state, eye, view_dir)`` returns, for each ``state.objects`` entry, the
  per-corner linear radiance (C, 3) float32 drawn with Gouraud interpolation
  (``eye``: perspective camera position, or ``view_dir``: unit direction toward
  an orthographic camera).
* A per-pixel GPU method overrides ``draw_objects`` instead: it returns a list
  of callables ``draw(view_projection)`` that draw each object into the bound
  framebuffer (depth test is set up by the caller); ``shade`` is then only used
  where per-vertex values are wanted (it may return None).
* ``scene_properties()`` returns ``{name: bpy.props.*Property(...)}`` added to
  ``scene.prt`` (its budgets and sliders); ``budget`` names the one swept by the
  benchmarks/report as ``(property name, values)``; ``draw_settings`` shows them.
  ``budget_between(lower, upper)`` (optional) gives a value strictly between two
  of those values (cheaper than ``upper``) or None: AUTO bisects with it to size
  an integer budget (light count, term count) to its error target.
* ``derive(job)`` (optional, no bpy, runs in the precompute worker after the
  visibility is traced; may raise ``core.visibility.Cancelled`` when
  ``job.cancel_requested``) returns method data for ``job.objects``;
  ``store(scene, job, derived)`` (main thread, last in the commit: the new
  visibility is stored by then) writes it to the .blend.  Both run for the active
  method only.  ``sync(state)`` (optional)
  loads stored data into ``state.objects[i].data`` each time a frame state is
  built.
* Hooks read by the frame state and the report, with their defaults here:
  ``draws_lamps``, ``last_choices()``, ``stability_cases()``; ``view_dependent(state)``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

REGISTRY: dict = {}


class Method(ABC):
    id = ""
    label = ""
    description = ""
    #: (scene.prt property, values swept by bench/report), or None.
    budget = None

    def scene_properties(self) -> dict:
        return {}

    def draw_settings(self, layout, prt):
        for name in self.scene_properties():
            layout.prop(prt, name)

    def budget_between(self, lower, upper):
        """A budget value strictly between ``lower`` and ``upper`` (two values of
        :attr:`budget`, ``lower`` the cheaper), cheaper than ``upper``; None when there
        is none (the default: AUTO then only tries the listed values)."""
        return None

    def view_dependent(self, state) -> bool:
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

    #: Whether ``shade``/``draw_objects`` draw Blender's point and spot lights
    #: (``state.lamps``); the frame state notes for other methods that they light the
    #: scene from the World and sun lamps only.
    draws_lamps = False

    def last_choices(self) -> list:
        """What the method chose per object for the newest frame (AUTO: dicts with
        ``object``, ``method``, ``setting``, ``value``, ``choice``, ``error``, ``seconds``,
        ``reason``), shown by the panel and the report; [] for a fixed method."""
        return []

    def stability_cases(self) -> list:
        """Hard cases of the stability table (``addon/report_cases.py``) that only concern
        this method, in the form of ``report_cases.BASE_CASES`` (e.g. SG sharpness
        1e-3...1e5 for a method with spherical Gaussians); the table names them
        ``"<name> [<method id>]"``.  None by default ([])."""
        return []


def glossy_or_layered(state) -> bool:
    """Whether any synced material has a glossy lobe or Principled layering (its
    radiance then depends on the view) -- the view dependence of per-vertex methods
    that shade the full core.brdf material."""
    return any(not m.is_diffuse_only or m.fresnel == "DIELECTRIC"
               for st in state.objects for m in st.materials)


def register(method: Method) -> Method:
    REGISTRY[method.id] = method
    return method


def get(method_id: str) -> Method:
    return REGISTRY.get(method_id) or REGISTRY["REFERENCE"]


def enum_items():
    return [(m.id, m.label, m.description) for m in REGISTRY.values()]


def scene_properties() -> dict:
    props = {}
    for m in REGISTRY.values():
        props.update(m.scene_properties())
    return props
