"""Precompute results stored in the .blend as packed float images.

Visibility is bit-packed per shading point (``core.visibility``), three bytes
per float32 (exact integers below 2**24), four floats per RGBA pixel.  Each
point owns a run of pixels; several points share an image row.  The image is
a packed, fake-user, Non-Color float buffer, so it round-trips exactly
through save/reload.
"""

import bpy
import numpy as np

from ..core.visibility import bytes_to_float24, float24_to_bytes

MAX_WIDTH = 4096
IMAGE_PREFIX = "PRT Visibility "
#: ID property marking every image this add-on wrote (what prt.clear removes)
OWNER_TAG = "prt_relight"
#: names of images written before OWNER_TAG existed
_OLD_PREFIXES = ("PRT Visibility ", "PRT Blocks ", "PRT RSL ", "PRT SSDF ")


def _layout(point_count: int, floats_per_point: int):
    ppp = floats_per_point // 4
    per_row = max(1, MAX_WIDTH // ppp)
    width = ppp * per_row
    height = max(1, -(-point_count // per_row))
    return width, height


def write_float_image(name: str, flat: np.ndarray, width: int = MAX_WIDTH, image=None):
    """Store ``flat`` float32 values (zero-padded to whole rows of ``width`` RGBA pixels)
    in a packed, fake-user, Non-Color, full-precision float image: exact round trip
    through save/reload.  ``image`` is reused when its size fits, else a new one is made."""
    flat = np.asarray(flat, dtype=np.float32).reshape(-1)
    height = max(1, -(-flat.size // (4 * width)))
    data = np.zeros(width * height * 4, dtype=np.float32)
    data[:flat.size] = flat
    img = image
    if img is not None and tuple(img.size) != (width, height):
        bpy.data.images.remove(img)
        img = None
    if img is None:
        img = bpy.data.images.new(name, width, height, alpha=True, float_buffer=True,
                                  is_data=True)
    img[OWNER_TAG] = True
    img.colorspace_settings.name = "Non-Color"
    img.alpha_mode = "CHANNEL_PACKED"
    img.use_fake_user = True
    img.use_half_precision = False
    img.pixels.foreach_set(data)
    img.update()
    img.pack()
    return img


def read_float_image(image) -> np.ndarray:
    """Every float of an image written by :func:`write_float_image` (with its padding)."""
    w, h = image.size
    flat = np.empty(w * h * 4, dtype=np.float32)
    image.pixels.foreach_get(flat)
    return flat


def create_visibility_image(name: str, bits: np.ndarray):
    """A new packed image holding ``bits`` (P, nbytes); the caller assigns it."""
    floats = bytes_to_float24(bits)                         # (P, F)
    P, F = floats.shape
    if F % 4:
        raise ValueError("floats per point must be a multiple of 4")
    width, height = _layout(P, F)
    flat = np.zeros(width * height * 4, dtype=np.float32)
    flat[: P * F] = floats.reshape(-1)
    return write_float_image(IMAGE_PREFIX + name, flat, width)


def read_visibility_image(image, point_count: int, nbytes: int) -> np.ndarray:
    """(P, nbytes) uint8 from an image made by :func:`create_visibility_image`."""
    F = nbytes // 3
    width, height = _layout(point_count, F)
    if tuple(image.size) != (width, height):
        raise ValueError(f"image '{image.name}' has size {tuple(image.size)}, "
                         f"expected {(width, height)}")
    flat = read_float_image(image)
    return float24_to_bytes(flat[: point_count * F].reshape(point_count, F))


def remove_image(image):
    if image is not None and image.users <= 1:
        bpy.data.images.remove(image)


def clear_all() -> int:
    """Remove everything the add-on stored in the .blend: its images (also those of
    deleted objects), the per-object links and ``prt_*`` ID properties, the scene's
    precompute record.  Returns how many objects had data."""
    count = 0
    for ob in bpy.data.objects:
        data = getattr(ob, "prt", None)
        had = data is not None and (data.visibility is not None or data.point_count)
        for key in [k for k in ob.keys() if k.startswith("prt_")]:
            del ob[key]
            had = True
        if data is not None:
            data.visibility = None
            data.point_count = 0
            data.resolution = 0
            data.fingerprint = ""
            data.precompute_id = ""
            data.coarse_warning = ""
        count += bool(had)
    for img in [i for i in bpy.data.images
                if i.get(OWNER_TAG) or i.name.startswith(_OLD_PREFIXES)]:
        bpy.data.images.remove(img)
    for scene in bpy.data.scenes:
        prt = getattr(scene, "prt", None)
        if prt is not None:
            prt.precomputed_resolution = 0
            prt.scene_fingerprint = ""
            prt.precompute_id = ""
            prt.precomputed_objects = 0
            prt.last_report = ""
            prt.auto_choice = ""
    return count
