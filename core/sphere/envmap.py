"""Environment lighting in Blender's world convention, resampled to cubemaps.

Convention (verified by baking a one-pixel sun in Cycles): a world direction
``d`` (Z up) reads an equirectangular Environment Texture at

    u = 0.5 - atan2(d.y, d.x) / (2*pi)          (column, left to right)
    v = acos(d.z) / pi                          (row, counted from the top row)

where the "top row" is the first row OpenImageIO returns (zenith on top).
A Mapping node of type POINT/VECTOR between the Texture Coordinate and the
Environment Texture turns ``d`` into ``R @ d`` before the lookup (TEXTURE type
applies the inverse), so the world radiance is ``L(d) = strength * E(R @ d)``.

Resampling to a cubemap is *by exact overlap* (:mod:`.resample`): the weight of pixel
``p`` in texel ``t`` is the solid angle of their intersection (the pixel a latitude-longitude
rectangle in texture space, the texel a great-circle quadrilateral turned by ``R``), so a
texel's radiance is ``sum_p w_pt L_p / Omega_t``, a constant image gives a constant cubemap
and the energy ``sum L dw`` is preserved (both to ~1e-10).  Every texel also keeps the
luminance-weighted mean direction of its light, ``sum_p Y_p int_{p & t} w dw /
sum_p Y_p w_pt``, equally exact: a one-pixel sun keeps its direction, split or not.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..common.cache import Cache, held
from .directions import Cubemap, cubemap
from .resample import LUMINANCE, ImageSums, texel_sums

try:  # OpenImageIO ships inside Blender 4.5/5.0, not 4.2.
    import OpenImageIO as oiio
except ImportError:  # pragma: no cover - depends on the host
    oiio = None


class EnvironmentError_(ValueError):
    """The environment cannot be used as lighting (message is for the user)."""


def have_openimageio() -> bool:
    return oiio is not None


def have_opencolorio() -> bool:
    """OpenImageIO built with OpenColorIO (colour conversion by a config file)."""
    flag = getattr(oiio, "supportsOpenColorIO", False)
    return bool(flag() if callable(flag) else flag)


def load_equirect(path: str) -> np.ndarray:
    """Read an equirectangular image as float32 (H, W, 3), top row first."""
    if oiio is None:
        raise EnvironmentError_("OpenImageIO is not available in this Blender; "
                                "pack the image or use Blender 4.5+")
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise EnvironmentError_(f"cannot open environment image {path!r}: {oiio.geterror()}")
    try:
        spec = inp.spec()
        pixels = inp.read_image(0, 0, 0, spec.nchannels, "float")
    finally:
        inp.close()
    if pixels is None or getattr(pixels, "size", 0) == 0:
        raise EnvironmentError_(f"cannot read pixels of {path!r}")
    pixels = np.asarray(pixels, dtype=np.float32).reshape(spec.height, spec.width, spec.nchannels)
    return as_rgb(pixels)


#: Blender's default working (scene-linear) colour space and its role name.
LINEAR_REC709 = "Linear Rec.709"
SCENE_LINEAR = "scene_linear"
#: Blender's colour space for data: read as stored, whatever the working space.
NON_COLOR = "Non-Color"


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """The exact piecewise sRGB EOTF (Cycles' ``color_srgb_to_linear``: negatives to 0)."""
    c = np.asarray(c, dtype=np.float32)
    return np.where(c < 0.04045, np.maximum(c, 0.0) / np.float32(12.92),
                    ((np.maximum(c, 0.04045) + np.float32(0.055)) / np.float32(1.055))
                    ** np.float32(2.4)).astype(np.float32)


def to_working_space(pixels: np.ndarray, colorspace: str, working_space: str = LINEAR_REC709,
                     config_path: str | None = None, is_data: bool = False) -> np.ndarray:
    """(H, W, 3) pixels stored in ``colorspace`` -> scene-linear ``working_space``.

    This is what Cycles does to a texture: Non-Color data and the working space itself
    pass unchanged; sRGB into Linear Rec.709 is the exact sRGB curve; anything else goes
    through OpenColorIO with the config at ``config_path`` (Blender's).  A display
    view transform (Filmic/AgX) is never involved.  Without OpenColorIO only those
    first cases work; others raise :class:`EnvironmentError_` naming the colour space.
    """
    px = as_rgb(pixels)
    if is_data or colorspace in (NON_COLOR, working_space, SCENE_LINEAR):
        return px
    if colorspace == "sRGB" and working_space == LINEAR_REC709:
        return srgb_to_linear(px)
    if not have_opencolorio() or not config_path:
        usable = f"Non-Color or {working_space}"
        if working_space == LINEAR_REC709:
            usable = "sRGB, " + usable
        raise EnvironmentError_(
            f"colour space '{colorspace}' needs OpenColorIO and Blender's colour config, "
            f"which this Blender lacks; set it to {usable}")
    out = oiio.ImageBufAlgo.colorconvert(oiio.ImageBuf(px), colorspace, working_space,
                                          unpremult=False, colorconfig=str(config_path))
    if out.has_error:
        raise EnvironmentError_(f"cannot convert colour space '{colorspace}' to "
                                f"'{working_space}': {out.geterror()}")
    return np.ascontiguousarray(out.get_pixels(oiio.FLOAT), dtype=np.float32).reshape(px.shape)


def as_rgb(pixels: np.ndarray) -> np.ndarray:
    """(H, W, C) -> (H, W, 3) float32 (grey repeated, alpha dropped)."""
    p = np.asarray(pixels, dtype=np.float32)
    if p.ndim == 2:
        p = p[:, :, None]
    if p.shape[2] == 1:
        p = np.repeat(p, 3, axis=2)
    elif p.shape[2] == 2:
        p = np.repeat(p[:, :, :1], 3, axis=2)
    return np.ascontiguousarray(p[:, :, :3])


def count_non_finite(pixels: np.ndarray) -> int:
    """Number of pixels with a NaN or infinite channel."""
    return int(np.count_nonzero(~np.isfinite(pixels).all(axis=-1)))


def euler_xyz_matrix(rx: float, ry: float, rz: float) -> np.ndarray:
    """Blender's Euler XYZ rotation matrix (``Rz @ Ry @ Rx``)."""
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def direction_to_equirect_uv(dirs: np.ndarray):
    """(u, v) in [0, 1) of texture-space directions; v counted from the top row."""
    d = np.asarray(dirs, dtype=np.float64)
    u = np.mod(0.5 - np.arctan2(d[..., 1], d[..., 0]) / (2.0 * np.pi), 1.0)
    v = np.arccos(np.clip(d[..., 2], -1.0, 1.0)) / np.pi
    return u, v


def equirect_directions(height: int, width: int, supersample: int = 1):
    """Texture-space directions and solid angles of (sub-)pixel centres.

    Returns ``(dirs (H*s, W*s, 3), solid_angles (H*s, W*s))``; the solid
    angles of all sub-pixels sum to 4*pi.
    """
    return _band_directions(height, width, int(supersample), 0, height)


# The newest environment images checked (and clamped at zero), per array: every frame's
# WorldLighting of an HDRI shares the exported pixel array (an array is not modified in
# place: new pixels are a new array), so a turned HDRI is not read twice more per frame
_CHECKED_IMAGES = Cache(2)


def _checked_image(image: np.ndarray) -> np.ndarray:
    """``image`` as (H, W, 3) radiance: refused with a NaN or infinite pixel, negative
    channels drawn as zero."""
    def check():
        img = as_rgb(image)
        bad = count_non_finite(img)
        if bad:
            raise EnvironmentError_(
                f"environment image has {bad} NaN/Inf pixel(s); fix or replace the image")
        return np.maximum(img, 0.0) if (img < 0).any() else img
    return held(_CHECKED_IMAGES, id(image), (image,), check)


@dataclass
class WorldLighting:
    """The world's radiance: ``strength * E(rotation @ d)`` or a constant colour.

    ``image`` is (H, W, 3) float32 top row first, or ``None`` for a uniform
    world of ``color``.  ``rotation`` maps world directions to texture space.
    """

    image: np.ndarray | None = None
    color: tuple = (0.05, 0.05, 0.05)
    strength: float = 1.0
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))

    def __post_init__(self):
        if self.image is not None:
            self.image = _checked_image(self.image)
        self.rotation = np.asarray(self.rotation, dtype=np.float64).reshape(3, 3)
        if not np.isfinite(self.strength):
            raise EnvironmentError_("world Background strength is not finite")

    def radiance(self, dirs: np.ndarray) -> np.ndarray:
        """Point-sampled (nearest pixel) radiance for world directions (..., 3)."""
        d = np.asarray(dirs, dtype=np.float64)
        if self.image is None:
            out = np.broadcast_to(np.asarray(self.color, dtype=np.float64), d.shape)
            return (self.strength * out).astype(np.float32)
        tex = d @ self.rotation.T
        u, v = direction_to_equirect_uv(tex)
        h, w, _ = self.image.shape
        col = np.clip((u * w).astype(np.int64), 0, w - 1)
        row = np.clip((v * h).astype(np.int64), 0, h - 1)
        return (self.strength * self.image[row, col]).astype(np.float32)

    def to_cubemap(self, resolution: int = 32) -> "CubeLighting":
        """Area-resampled lighting per cubemap texel."""
        cube = cubemap(resolution)
        if self.image is None:
            rad = np.broadcast_to(self.strength * np.asarray(self.color, np.float32),
                                  (cube.size, 3)).astype(np.float32)
            return CubeLighting(rad, np.array(cube.mean_directions))
        lighting = resample_equirect_to_cubemap(self.image, cube, self.rotation)
        lighting.radiance *= np.float32(self.strength)
        return lighting

    def total_power(self) -> np.ndarray:
        """Integral of radiance over the sphere (RGB), by exact pixel solid angles."""
        if self.image is None:
            return 4.0 * np.pi * self.strength * np.asarray(self.color, dtype=np.float64)
        h, w, _ = self.image.shape
        _, sa = equirect_directions(h, w, 1)
        return self.strength * np.einsum("hw,hwc->c", sa, self.image.astype(np.float64))


@dataclass
class CubeLighting:
    """Lighting on cubemap texels.

    ``radiance`` (D, 3) float32: mean radiance of each texel (energy / solid angle).
    ``directions`` (D, 3): luminance-weighted mean direction *vector* of the light
    inside each texel (length <= 1).  ``max(0, n . directions[k])`` is the texel's
    exact mean cosine when the texel lies above the horizon of ``n``, and a
    one-pixel sun keeps its true direction instead of the texel centre's.
    """

    radiance: np.ndarray
    directions: np.ndarray

    @property
    def unit_directions(self) -> np.ndarray:
        d = self.directions
        return d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-30)


# What the resampling keeps of the newest image (:class:`ImageSums`: per-column sums, at
# most resample.SUMS_BUDGET bytes): a turned world (Mapping rotation: relit frames) only
# redoes the geometry.
_RESAMPLE_CACHE = Cache(1)


def _image_sums(img: np.ndarray) -> ImageSums:
    """:class:`ImageSums` of ``img``, kept for the newest image."""
    return held(_RESAMPLE_CACHE, (id(img), img.shape), (img,), lambda: ImageSums(img))


def resample_equirect_to_cubemap(image: np.ndarray, cube: Cubemap, rotation=None) -> CubeLighting:
    """Exact area resampling of an equirect image to ``cube`` texels (module docstring).

    What does not depend on the rotation is kept between calls for the same image array,
    so turning the world only redoes the geometry.  The image must not be modified in
    place between calls (a new array is a new image)."""
    img = np.asarray(image, dtype=np.float32)      # the same array when already float32
    R = np.eye(3) if rotation is None else np.asarray(rotation, dtype=np.float64)
    energy, moment = texel_sums(_image_sums(img), cube.resolution, R)
    lum = energy @ LUMINANCE
    lit = lum > 0
    dirs = np.array(cube.mean_directions)
    dirs[lit] = (moment[lit] @ R) / lum[lit, None]     # texture -> world: R.T @ m
    return CubeLighting((energy / cube.solid_angles[:, None]).astype(np.float32), dirs)


def equirect_mip_sizes(height: int, width: int, min_width: int = 4) -> list:
    """``(H_l, W_l)`` of the levels below an equirect of ``height`` x ``width`` pixels,
    each half its parent's size rounded up, down to ``min_width`` columns."""
    sizes = []
    h, w = int(height), int(width)
    while w > min_width and h > 1:
        h, w = (h + 1) // 2, (w + 1) // 2
        sizes.append((h, w))
    return sizes


#: Widest equirect the engine uploads to the GPU to draw the background and the sharp
#: lobes' level 0 (a 16k image is 2 GiB as RGBA32F, more than a GPU texture may hold);
#: wider images are drawn from :func:`display_equirect`.  The lighting is always
#: resampled from the full image.
DISPLAY_MAX_WIDTH = 8192
_DISPLAY_CACHE = Cache(1)


def halve_equirect(image: np.ndarray, rows: int = 512) -> np.ndarray:
    """One level below an equirect (H, W, 3): each pixel the solid-angle-weighted mean of
    its (up to) 2 x 2 parents, as :func:`equirect_mip_atlas` makes its levels (energy kept);
    float32, computed ``rows`` output rows at a time so a 16k image needs no float64 copy."""
    img = np.asarray(image)
    H, W = img.shape[:2]
    h, w = (H + 1) // 2, (W + 1) // 2
    edges = np.cos(np.linspace(0.0, np.pi, H + 1))
    band = edges[:-1] - edges[1:]
    out = np.empty((h, w, 3), np.float32)
    for r0 in range(0, h, rows):
        r1 = min(h, r0 + rows)
        a, b = 2 * r0, min(H, 2 * r1)
        padded = np.zeros((2 * (r1 - r0), 2 * w, 3))
        weight = np.zeros((2 * (r1 - r0), 2 * w))
        padded[:b - a, :W] = img[a:b, :, :3] * band[a:b, None, None]
        weight[:b - a, :W] = band[a:b, None]
        num = padded.reshape(r1 - r0, 2, w, 2, 3).sum(axis=(1, 3))
        den = weight.reshape(r1 - r0, 2, w, 2).sum(axis=(1, 3))
        out[r0:r1] = num / np.maximum(den, 1e-300)[..., None]
    return out


def display_equirect(image: np.ndarray, max_width: int | None = None) -> np.ndarray:
    """``image`` halved (:func:`halve_equirect`) until at most ``max_width`` columns wide
    (default :data:`DISPLAY_MAX_WIDTH`): what the GPU draws of a world image; the image
    itself when it is narrow enough.  Kept for the newest image."""
    limit = DISPLAY_MAX_WIDTH if max_width is None else int(max_width)
    if image.shape[1] <= limit:
        return image
    key = (id(image), image.shape, limit)
    got = _DISPLAY_CACHE.get(key)
    if got is not None and got[0] is image:
        return got[1]
    level = image
    while level.shape[1] > limit:
        level = halve_equirect(level)
    _DISPLAY_CACHE[key] = (image, level)
    return level


def equirect_mip_atlas(image: np.ndarray, min_width: int = 4) -> np.ndarray:
    """The levels 1, 2, ... below an equirect image (H, W, 3), stacked top to bottom in
    one RGBA float32 array of ``W_1`` columns (level ``l`` in its first ``W_l``
    columns; sizes from :func:`equirect_mip_sizes`).  A child pixel is the
    solid-angle-weighted mean of its (up to) 2 x 2 parents, so every level keeps the
    image's energy (exactly for even sizes; an odd size stretches its level by half a
    pixel) and a lookup at a sample's footprint averages the radiance over it (filtered
    importance sampling).  An image too small for a level gives 1 x 1."""
    level = np.asarray(image, dtype=np.float64)
    sizes = equirect_mip_sizes(level.shape[0], level.shape[1], min_width)
    if not sizes:
        return np.zeros((1, 1, 4), np.float32)
    out = np.zeros((sum(h for h, _ in sizes), sizes[0][1], 4), np.float32)
    out[..., 3] = 1.0
    row = 0
    for h, w in sizes:
        H, W = level.shape[:2]
        edges = np.cos(np.linspace(0.0, np.pi, H + 1))
        band = (edges[:-1] - edges[1:])                            # row solid angle / dphi
        padded = np.zeros((2 * h, 2 * w, 3))
        weight = np.zeros((2 * h, 2 * w))
        padded[:H, :W] = level * band[:, None, None]
        weight[:H, :W] = band[:, None]
        num = padded.reshape(h, 2, w, 2, 3).sum(axis=(1, 3))
        den = weight.reshape(h, 2, w, 2).sum(axis=(1, 3))
        level = num / np.maximum(den, 1e-300)[..., None]
        out[row:row + h, :w, :3] = level
        row += h
    return out


def _band_directions(h, w, s, r0, r1):
    theta_edges = np.linspace(r0 * np.pi / h, r1 * np.pi / h, (r1 - r0) * s + 1)
    theta = 0.5 * (theta_edges[:-1] + theta_edges[1:])
    ws = w * s
    u = (np.arange(ws) + 0.5) / ws
    phi = (0.5 - u) * 2.0 * np.pi
    band = (np.cos(theta_edges[:-1]) - np.cos(theta_edges[1:])) * (2.0 * np.pi / ws)
    st, ct = np.sin(theta), np.cos(theta)
    dirs = np.empty((len(theta), ws, 3))
    dirs[..., 0] = st[:, None] * np.cos(phi)[None, :]
    dirs[..., 1] = st[:, None] * np.sin(phi)[None, :]
    dirs[..., 2] = ct[:, None]
    return dirs, np.broadcast_to(band[:, None], dirs.shape[:2])
