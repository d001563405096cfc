"""Relit frames: the per-frame time that the report and AUTO measure (bpy-free).

A relit frame turns the environment about +Z (as the World's Mapping rotation does) to an
angle not drawn before, so everything kept per lighting (REFERENCE's diffuse sums, the
resampled cubemap, the wavelet lighting, SSDF_SG's scene fit, RSL's rotated lights) is made
again as it is while relighting, while per-geometry data (transfer) stays warm.  Every
caller draws its angles from the one sequence :func:`next_angle`, so no two timed frames
of a session share a lighting.
"""

from __future__ import annotations

import copy
import itertools
import time

import numpy as np

from ...core.sphere import envmap

# frames turned so far in this session (``next`` on a count is atomic)
_TURNS = itertools.count(1)


def next_angle() -> float:
    """The angle of the next relit frame (radians; 0.42, 0.79, 1.16, ...: never the
    same twice, never a whole turn)."""
    return 0.05 + 0.37 * next(_TURNS)


def rotated_world(world: envmap.WorldLighting, angle: float) -> envmap.WorldLighting:
    """``world`` turned by ``angle`` about +Z (same pixels, a new lighting key)."""
    c, s = np.cos(angle), np.sin(angle)
    out = copy.copy(world)
    out.rotation = np.asarray(world.rotation) @ np.array([[c, -s, 0.0], [s, c, 0.0],
                                                           [0.0, 0.0, 1.0]])
    return out


def relit_times(states, frame, rounds: int, warmup: bool = True,
                clock=time.perf_counter) -> list:
    """Seconds of ``rounds`` relit frames per frame state (after one untimed round when
    ``warmup``): ``frame(state)`` draws or shades one frame after the state's world is
    turned to :func:`next_angle`.  With several states the frames are interleaved (one
    each per round), so the machine's load weighs on each alike.  The background texture
    is kept (same pixels); every state's world is put back afterwards.  ``clock``: the
    seconds read around each frame (tests give a virtual one)."""
    times = [[] for _ in states]
    saved = [(st.world, st.background) for st in states]
    try:
        for k in range(rounds + int(warmup)):
            for i, st in enumerate(states):
                world, background = saved[i]
                st.world = rotated_world(world, next_angle())
                if background is not None:
                    st.background = (st.world, background[1])
                t0 = clock()
                frame(st)
                if k >= int(warmup):
                    times[i].append(clock() - t0)
    finally:
        for st, (world, background) in zip(states, saved):
            st.world, st.background = world, background
    return times
