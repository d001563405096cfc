"""Spatially varying colour inputs: image textures on UV maps and colour attributes (pure
numpy; the GLSL twin is ``shaders/lib/texture.glsl``).

A colour input of a material slot is one :class:`ColorSource`: an :class:`ImageTexture`
read at the corner's UV (through a Mapping node's 2D transform), or a mesh colour
attribute interpolated across the triangle, optionally combined with a constant colour
by a Mix node (``MIX`` by a factor, or ``MULTIPLY``).  Sampling follows Blender's Image
Texture node: texel centres at ``((i + 0.5) / W, (j + 0.5) / H)`` with row 0 at v = 0;
*Closest*, *Linear* (bilinear) and *Cubic* (uniform cubic B-spline, as Cycles'
``interp_cubic``); *Repeat*, *Extend* (clamp to the edge), *Clip* (transparent black
outside [0, 1]) and *Mirror*.

A scalar input (Principled *Roughness*, *Metallic*, *Specular IOR Level*; Glossy
*Roughness*) driven by one of those is a :class:`ScalarSource`: the colour read as a float
the way Blender converts a colour socket into a float one (its luminance).  Per-vertex
consumers take a shading point's value (the mean over its corners, :func:`point_values`),
quantized into a few material variants (:func:`quantize`).

A surface node's *Normal* input driven by a Normal Map node (tangent space) or a Bump node
reading an image is a :class:`NormalSource`; :func:`perturbed_normals` is the shaders'
per-pixel normal (``texture.glsl`` ``mapped_normal``), as Cycles' ``svm_node_normal_map``
and ``svm_node_set_bump`` compute it, except that the bump's height derivative is taken by
finite differences of the texture in UV space (one texel each way) instead of Cycles'
screen-space differences.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

INTERPOLATIONS = ("CLOSEST", "LINEAR", "CUBIC")
EXTENSIONS = ("REPEAT", "EXTEND", "CLIP", "MIRROR")


@dataclass
class ImageTexture:
    pixels: np.ndarray                         # (H, W, 4) float32, linear, row 0 at v = 0
    uv_map: str = ""                           # "" = the mesh's render UV map
    transform: np.ndarray = field(default_factory=lambda: np.array([[1.0, 0.0, 0.0],
                                                                    [0.0, 1.0, 0.0]]))
    interpolation: str = "LINEAR"
    extension: str = "REPEAT"
    name: str = ""

    def __post_init__(self):
        px = np.asarray(self.pixels, dtype=np.float32)
        if px.ndim != 3 or px.shape[2] != 4:
            raise ValueError("texture pixels must be (H, W, 4)")
        if not np.isfinite(px).all():
            raise ValueError(f"texture '{self.name}' has NaN/Inf pixels")
        self.pixels = np.ascontiguousarray(px)
        self.transform = np.asarray(self.transform, dtype=np.float64).reshape(2, 3)
        self.interpolation = str(self.interpolation).upper()
        if self.interpolation not in INTERPOLATIONS:
            self.interpolation = "LINEAR"
        self.extension = str(self.extension).upper()
        if self.extension not in EXTENSIONS:
            self.extension = "REPEAT"


@dataclass
class ColorSource:
    """What drives one colour input: a texture or an attribute, maybe mixed with a colour.

    ``mix``: None, or ``(mode, factor, colour, source_first)``: Blender's Mix node in
    colour mode, ``MIX``: ``(1 - f) A + f B``, ``MULTIPLY``: ``A (1 - f + f B)``, with A,
    B the node's inputs (the source is A when ``source_first``)."""

    texture: ImageTexture | None = None
    attribute: str = ""
    mix: tuple | None = None

    def combine(self, colour: np.ndarray) -> np.ndarray:
        """The input's value from the source's colour (..., 3|4), as the Mix node does."""
        c = np.asarray(colour, dtype=np.float64)[..., :3]
        if self.mix is None:
            return c
        mode, f, other, first = self.mix
        other = np.asarray(other, dtype=np.float64)[:3]
        a, b = (c, other) if first else (other, c)
        if mode == "MULTIPLY":
            return a * (1.0 - f + f * b)
        return (1.0 - f) * a + f * b


def transformed_uv(texture: ImageTexture, uv: np.ndarray) -> np.ndarray:
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    return uv @ texture.transform[:, :2].T + texture.transform[:, 2]


def _wrap(i, n, extension):
    if extension == "REPEAT":
        return np.mod(i, n)
    if extension == "MIRROR":
        m = np.mod(i, 2 * n)
        return np.where(m < n, m, 2 * n - 1 - m)
    return np.clip(i, 0, n - 1)


def _bspline(t):
    """Uniform cubic B-spline weights of the four taps around a fractional position t."""
    t2, t3 = t * t, t * t * t
    return ((1.0 - t) ** 3 / 6.0, (3.0 * t3 - 6.0 * t2 + 4.0) / 6.0,
            (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) / 6.0, t3 / 6.0)


def sample(texture: ImageTexture, uv: np.ndarray) -> np.ndarray:
    """RGBA (P, 4) of ``texture`` at UVs (P, 2), as Blender's Image Texture node reads it."""
    img = texture.pixels.astype(np.float64)
    H, W = img.shape[:2]
    st = transformed_uv(texture, uv)
    x, y = st[:, 0] * W - 0.5, st[:, 1] * H - 0.5
    ext = texture.extension
    if texture.interpolation == "CLOSEST":
        out = img[_wrap(np.floor(y + 0.5).astype(np.int64), H, ext),
                  _wrap(np.floor(x + 0.5).astype(np.int64), W, ext)]
    elif texture.interpolation == "CUBIC":
        x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
        wx, wy = _bspline(x - x0), _bspline(y - y0)
        out = np.zeros((len(st), 4))
        for j in range(4):
            for i in range(4):
                out += (wx[i] * wy[j])[:, None] * img[_wrap(y0 - 1 + j, H, ext),
                                                      _wrap(x0 - 1 + i, W, ext)]
    else:
        x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
        fx, fy = (x - x0)[:, None], (y - y0)[:, None]
        xa, xb = _wrap(x0, W, ext), _wrap(x0 + 1, W, ext)
        ya, yb = _wrap(y0, H, ext), _wrap(y0 + 1, H, ext)
        out = ((img[ya, xa] * (1 - fx) + img[ya, xb] * fx) * (1 - fy)
               + (img[yb, xa] * (1 - fx) + img[yb, xb] * fx) * fy)
    if ext == "CLIP":
        outside = (st[:, 0] < 0.0) | (st[:, 0] > 1.0) | (st[:, 1] < 0.0) | (st[:, 1] > 1.0)
        out[outside] = 0.0
    return out


def mean_colour(source: ColorSource, corner_colours=None) -> np.ndarray:
    """An average RGB of the input (what consumers that cannot vary it per pixel use):
    the texture's pixel mean, or the attribute's corner mean, through the mix."""
    if source.texture is not None:
        c = source.texture.pixels[..., :3].reshape(-1, 3).mean(axis=0)
    elif corner_colours is not None and len(corner_colours):
        c = np.asarray(corner_colours, dtype=np.float64)[:, :3].mean(axis=0)
    else:
        c = np.ones(3)
    return np.maximum(source.combine(c), 0.0)


#: Blender's implicit colour -> float conversion (Cycles' ``linear_rgb_to_gray``: the
#: luminance weights of the Linear Rec.709 working space)
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])

#: the scalar inputs read per pixel / per point, with their ranges (Cycles' clamps)
SCALAR_INPUTS = {"Roughness": (0.0, 1.0), "Metallic": (0.0, 1.0),
                 "Specular IOR Level": (0.0, 1.0)}


@dataclass
class ScalarSource:
    """A scalar input driven by a :class:`ColorSource` (its Color output, a float by
    :data:`LUMINANCE`), clamped to the input's range."""

    source: ColorSource
    input: str = "Roughness"

    def value(self, colour: np.ndarray) -> np.ndarray:
        lo, hi = SCALAR_INPUTS[self.input]
        return np.clip(self.source.combine(colour) @ LUMINANCE, lo, hi)


def corner_colours(source: ColorSource, values: np.ndarray) -> np.ndarray:
    """RGBA (C, 4) of a source at each corner: the texture at the corner UVs (C, 2), or the
    attribute colours (C, 4) themselves."""
    if source.texture is not None:
        return sample(source.texture, values)
    return np.asarray(values, dtype=np.float64)


def point_values(scalar: ScalarSource, values: np.ndarray, point_of_corner: np.ndarray,
                 count: int) -> np.ndarray:
    """(P,) a scalar input per shading point: the mean of its corners' values (NaN for a
    point without corners)."""
    v = scalar.value(corner_colours(scalar.source, values)[:, :3])
    total = np.bincount(point_of_corner, weights=v, minlength=count)
    n = np.bincount(point_of_corner, minlength=count)
    with np.errstate(invalid="ignore", divide="ignore"):
        return total / n


def quantize(values: np.ndarray, levels: int):
    """(levels used (L,), index per value): ``values`` rounded to ``levels`` evenly spaced
    values between their minimum and maximum (error at most half a step)."""
    v = np.asarray(values, dtype=np.float64)
    lo, hi = float(np.nanmin(v)), float(np.nanmax(v))
    if hi - lo < 1e-6 or levels < 2:
        return np.array([0.5 * (lo + hi)]), np.zeros(len(v), np.int64)
    grid = np.linspace(lo, hi, levels)
    idx = np.clip(np.rint((np.nan_to_num(v, nan=lo) - lo) / (hi - lo) * (levels - 1)), 0,
                  levels - 1).astype(np.int64)
    return grid, idx


def material_at(material, values: dict, principled: dict | None = None):
    """``material`` (core.shading.brdf.Material) with the scalar inputs ``values`` ({input: value});
    ``principled``: the Principled node's constant IOR, Specular Tint and distribution, which
    a *Specular IOR Level* needs (it remaps the IOR and the dielectric F0)."""
    from ..shading import materials
    rough = float(values.get("Roughness", material.roughness))
    metal = float(values.get("Metallic", material.metallic))
    if "Specular IOR Level" in values and principled is not None:
        out = materials.principled_material(
            base_color=material.diffuse_albedo, metallic=metal, roughness=rough,
            ior=principled["IOR"], specular_ior_level=float(values["Specular IOR Level"]),
            specular_tint=principled["Specular Tint"], distribution=principled["distribution"])
        return replace(out, per_pixel_lobe=material.per_pixel_lobe)
    return replace(material, roughness=min(max(rough, 0.0), 1.0),
                   metallic=min(max(metal, 0.0), 1.0))


def point_variants(materials: list, points, slots: dict, principled: dict, levels: int = 32):
    """Per-vertex materials of textured scalar inputs: ``(materials, point materials (P,),
    slot of each material)``.  ``slots``: {slot: {input: (P,) value per point}} (from
    :func:`point_values`); each such slot's points get a variant of its material at their
    values quantized (:func:`quantize`, at most ``levels`` variants per slot), appended to
    ``materials``; ``principled``: {slot: :func:`material_at`'s constants}."""
    out = list(materials)
    slot_of = list(range(len(materials)))
    point_mat = np.asarray(points.materials).copy()
    for slot, inputs in slots.items():
        sel = np.nonzero(point_mat == slot)[0]
        if not len(sel) or slot >= len(materials):
            continue
        q = max(2, int(round(levels ** (1.0 / len(inputs)))))
        grids, combo = {}, np.zeros(len(sel), np.int64)
        for name, values in inputs.items():
            grids[name], idx = quantize(values[sel], q)
            combo = combo * q + idx
        used, which = np.unique(combo, return_inverse=True)
        for k, c in enumerate(used):
            vals, rest = {}, int(c)
            for name in reversed(list(inputs)):
                grid = grids[name]
                vals[name] = float(grid[min(rest % q, len(grid) - 1)])
                rest //= q
            out.append(material_at(materials[slot], vals, principled.get(slot)))
            slot_of.append(slot)
            point_mat[sel[which == k]] = len(out) - 1
    return out, point_mat, np.asarray(slot_of, np.int64)


# --------------------------------------------------------------------------- normals

NORMAL_KINDS = ("NORMAL_MAP", "BUMP")


@dataclass
class NormalSource:
    """What drives a surface node's Normal: a Normal Map node (tangent space; its Color an
    image) or a Bump node (its Height the image's colour as a float, :data:`LUMINANCE`).
    ``distance`` is the Bump node's Distance, negated when it is inverted."""

    kind: str
    source: ColorSource
    strength: float = 1.0
    distance: float = 1.0


def _unit(v):
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 1e-30, v / np.where(n > 1e-30, n, 1.0), 0.0)


def tangent_space_normals(colour, normal, tangent, sign, strength=1.0):
    """Cycles' tangent-space Normal Map: ``x = 2 c - 1``, ``B = sign N x T``,
    ``n = normalize(x T + y B + z N)`` with the (unnormalised) interpolated N and T, then
    ``normalize(N + strength (n - N))`` when strength is not 1 (N unit)."""
    x = 2.0 * np.asarray(colour, np.float64)[..., :3] - 1.0
    N = np.asarray(normal, np.float64)
    T = np.asarray(tangent, np.float64)
    B = np.asarray(sign, np.float64)[..., None] * np.cross(N, T)
    n = _unit(x[..., :1] * T + x[..., 1:2] * B + x[..., 2:3] * N)
    Nu = _unit(N)
    if strength != 1.0:
        n = _unit(Nu + (n - Nu) * max(float(strength), 0.0))
    return np.where(np.linalg.norm(n, axis=-1, keepdims=True) > 0.0, n, Nu)


def height(source: ColorSource, uv) -> np.ndarray:
    """(P,) the Bump node's Height at UVs: the image's colour as a float, unclamped."""
    return source.combine(sample(source.texture, uv)[:, :3]) @ LUMINANCE


def height_derivatives(source: ColorSource, uv) -> np.ndarray:
    """(P, 2) dh/du, dh/dv by central differences one texel each way (the step in u and
    v is one texel of the mapped image along that axis)."""
    tex = source.texture
    H, W = tex.pixels.shape[:2]
    A = tex.transform[:, :2]
    uv = np.asarray(uv, np.float64).reshape(-1, 2)
    out = np.empty_like(uv)
    for axis in range(2):
        step = 1.0 / max(float(np.hypot(A[0, axis] * W, A[1, axis] * H)), 1e-12)
        d = np.zeros(2)
        d[axis] = step
        out[:, axis] = (height(source, uv + d) - height(source, uv - d)) / (2.0 * step)
    return out


def surface_gradient(normal, dp1, dp2, dh1, dh2):
    """The height's gradient in N's plane from its change dh1, dh2 along two surface steps
    dp1, dp2 (Cycles' Bump: ``(dh1 R1 + dh2 R2) / det``, R1 = dp2 x N, R2 = N x dp1; with a
    triangle's edges and the UV derivative this is exact on the triangle)."""
    N = np.asarray(normal, np.float64)
    r1, r2 = np.cross(dp2, N), np.cross(N, dp1)
    det = np.sum(dp1 * r1, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        g = (np.asarray(dh1)[..., None] * r1 + np.asarray(dh2)[..., None] * r2) / det
    return np.where(np.abs(det) > 1e-30, g, 0.0)


def bump_normals(normal, gradient, distance=1.0, strength=1.0):
    """Cycles' Bump: ``n = normalize(N - distance grad h)``, then
    ``normalize(s n + (1 - s) N)`` (N unit, s the strength, at least 0)."""
    N = _unit(np.asarray(normal, np.float64))
    n = _unit(N - float(distance) * np.asarray(gradient, np.float64))
    s = max(float(strength), 0.0)
    n = _unit(s * n + (1.0 - s) * N)
    return np.where(np.linalg.norm(n, axis=-1, keepdims=True) > 0.0, n, N)


def valid_reflection_normal(ng, o, n):
    """Cycles' bump map correction (``ensure_valid_specular_reflection``): ``n`` turned
    toward ``ng`` just enough that the mirror reflection of the view ``o`` is at least
    ``min(0.9 o.ng, 0.01)`` above the surface (all unit, (P, 3))."""
    ng, o, n = (np.asarray(a, np.float64) for a in (ng, o, n))
    r = 2.0 * np.sum(n * o, axis=-1, keepdims=True) * n - o
    iz = np.sum(o * ng, axis=-1, keepdims=True)
    t = np.minimum(0.9 * iz, 0.01)
    x = _unit(n - np.sum(n * ng, axis=-1, keepdims=True) * ng)
    ix = np.sum(o * x, axis=-1, keepdims=True)
    a = ix * ix + iz * iz
    b = 2.0 * (a + iz * t)
    c = (t + iz) ** 2
    root = np.sqrt(np.maximum(b * b - 4.0 * a * c, 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        nz2 = np.where(ix < 0.0, 0.25 * (b + root) / a, 0.25 * (b - root) / a)
    bent = np.sqrt(np.maximum(1.0 - nz2, 0.0)) * x + np.sqrt(np.maximum(nz2, 0.0)) * ng
    return np.where(np.sum(ng * r, axis=-1, keepdims=True) >= t, n, bent)


def bump_shadowing(ns, n, i):
    """Cycles' (5.0) factor on a diffuse closure whose normal ``n`` is not the smooth
    surface normal ``ns`` (Conty Estevez et al. 2019, a microfacet shadowing function for
    the bump terminator): GGX's Smith G1 at ``|ns.i|`` with ``alpha^2 = min(tan^2 d / 8, 1)``,
    d the angle between ns and n; 0 when i and n are on different sides of ns."""
    ns, n, i = (np.asarray(a, np.float64) for a in (ns, n, i))
    cos_i = np.abs(np.sum(ns * i, axis=-1))
    cos_d = np.minimum(np.abs(np.sum(ns * n, axis=-1)), 1.0)
    side = np.sum(ns * i, axis=-1) * np.sum(ns * n, axis=-1) * np.sum(n * i, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        a2 = np.clip(0.125 * (1.0 / (cos_d * cos_d) - 1.0), 0.0, 1.0)
        t2 = 1.0 / (cos_i * cos_i) - 1.0
        g1 = 2.0 / (1.0 + np.sqrt(1.0 + a2 * t2))
    out = np.where((cos_d >= 1.0) | (cos_i >= 1.0), 1.0, np.where(cos_i < 1e-6, 0.0, g1))
    return np.where(np.all(ns == n, axis=-1), 1.0, np.where(side < 0.0, 0.0, out))


def perturbed_normals(normal_source: NormalSource, uv, normal, tangent=None, sign=None,
                      dp=None, duv=None):
    """(P, 3) the mapped normal at P points: ``uv`` (P, 2), the interpolated ``normal``;
    a Normal Map needs ``tangent`` (P, 3) and ``sign`` (P,), a Bump ``dp`` (P, 2, 3) two
    surface steps (a triangle's edges) and ``duv`` (P, 2, 2) the UV change along them."""
    src = normal_source.source
    if normal_source.kind == "NORMAL_MAP":
        colour = src.combine(sample(src.texture, uv))
        return tangent_space_normals(colour, normal, tangent, sign, normal_source.strength)
    dh = height_derivatives(src, uv)
    dh1 = np.sum(dh * duv[:, 0], axis=-1)
    dh2 = np.sum(dh * duv[:, 1], axis=-1)
    g = surface_gradient(normal, dp[:, 0], dp[:, 1], dh1, dh2)
    return bump_normals(normal, g, normal_source.distance, normal_source.strength)


def dilate(image: np.ndarray, covered: np.ndarray, pixels: int):
    """A baked map's margin: ring by ring, up to ``pixels`` times, each texel no triangle
    covers next to one that is takes the mean of its covered 4-neighbours (so bilinear
    filtering and mip maps at a UV island's edge read the island, not black).  Returns
    (image, covered) anew."""
    img = np.array(image, dtype=np.float32, copy=True)
    done = np.array(covered, dtype=bool, copy=True)
    for _ in range(max(0, int(pixels))):
        pad_v = np.pad(img * done[..., None], ((1, 1), (1, 1), (0, 0)))
        pad_d = np.pad(done, 1).astype(np.float32)
        total = pad_v[:-2, 1:-1] + pad_v[2:, 1:-1] + pad_v[1:-1, :-2] + pad_v[1:-1, 2:]
        count = pad_d[:-2, 1:-1] + pad_d[2:, 1:-1] + pad_d[1:-1, :-2] + pad_d[1:-1, 2:]
        new = ~done & (count > 0)
        if not new.any():
            break
        img[new] = total[new] / count[new][:, None]
        done |= new
    return img, done
