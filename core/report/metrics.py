"""Speed-against-error report: metrics, images, Pareto frontier, SVG plot, HTML.

Numpy and the standard library, PNG files written with OpenImageIO (guarded as in
:mod:`.envmap`: the add-on writes them with Blender's image API where it is missing), so
the same code serves the ``prt.report`` operator, ``bench/report.py`` and the tests.

Images handed to this module are linear RGBA float arrays, **top row first**;
pixels with alpha > 0.5 in the reference image are the ones measured (the
objects, not the world background).
"""

from __future__ import annotations

import html
import math
import pathlib

import numpy as np

try:  # OpenImageIO ships inside Blender 4.5/5.0, not 4.2.
    import OpenImageIO as oiio
except ImportError:  # pragma: no cover - depends on the Blender build
    oiio = None

# --------------------------------------------------------------------- metrics


def coverage_mask(reference: np.ndarray, alpha_min: float = 0.5) -> np.ndarray:
    """Pixels measured: the reference's alpha > ``alpha_min`` (all pixels for RGB)."""
    ref = np.asarray(reference)
    if ref.ndim == 3 and ref.shape[-1] > 3:
        return ref[..., 3] > alpha_min
    return np.ones(ref.shape[:2], dtype=bool)


def rel_l2(image: np.ndarray, reference: np.ndarray, mask: np.ndarray | None = None) -> float:
    """Relative L2 error ``‖a − b‖ / ‖b‖`` over the RGB of the masked pixels.

    With an all-black reference (``‖b‖ = 0``) the result is ``‖a‖`` itself (0 when
    both are black) so it never divides by zero; non-finite input gives ``inf``.
    """
    if mask is None:
        mask = coverage_mask(reference)
    a = np.asarray(image)[..., :3][mask].astype(np.float64)
    b = np.asarray(reference)[..., :3][mask].astype(np.float64)
    if not (np.isfinite(a).all() and np.isfinite(b).all()):
        return float("inf")
    nb = float(np.linalg.norm(b))
    diff = float(np.linalg.norm(a - b))
    return diff / nb if nb > 0.0 else diff


def rel_l2_converged(image: np.ndarray, frames) -> tuple[float, float, float]:
    """Error against a converged reference estimated from ``frames``, N >= 2 renders of it
    with different seeds: ``(rel-L2 against their mean, the mean's own noise, rel-L2 against
    the converged frame)``.  ``E|o - m|^2 = |o - t|^2 + s^2 / N`` (``t`` converged, ``s^2``
    the per-seed variance, estimated without bias by ``sum |c_i - m|^2 / (N - 1)``), so
    ``|o - t| ~ sqrt(|o - m|^2 - s^2 / N)``; over the pixels where the frames' mean alpha
    is > 0.5, RGB."""
    F = np.stack([np.asarray(f) for f in frames])
    n = len(F)
    if n < 2:
        raise ValueError("rel_l2_converged needs at least two seeds' frames")
    C = F[..., :3].astype(np.float64)
    mean = C.mean(0)
    mask = F[..., 3].mean(0) > 0.5 if F.shape[-1] > 3 else np.ones(mean.shape[:2], bool)
    norm = float((mean ** 2).sum(-1)[mask].sum())
    var = float(sum(((c - mean) ** 2).sum(-1)[mask].sum() for c in C)) / (n - 1)
    e2 = float(((np.asarray(image)[..., :3] - mean) ** 2).sum(-1)[mask].sum())
    return (math.sqrt(e2 / norm), math.sqrt(var / n / norm),
            math.sqrt(max(e2 - var / n, 0.0) / norm))


def psnr(image: np.ndarray, reference: np.ndarray, mask: np.ndarray | None = None) -> float:
    """Peak signal-to-noise ratio in dB, the peak being the reference's largest value
    among the masked pixels (``inf`` for identical images)."""
    if mask is None:
        mask = coverage_mask(reference)
    a = np.asarray(image)[..., :3][mask].astype(np.float64)
    b = np.asarray(reference)[..., :3][mask].astype(np.float64)
    if a.size == 0:
        return float("nan")
    mse = float(np.mean((a - b) ** 2))
    peak = float(b.max()) if b.size else 0.0
    if mse == 0.0:
        return float("inf")
    if not np.isfinite(mse) or peak <= 0.0:
        return float("-inf") if not np.isfinite(mse) else float("nan")
    return 10.0 * math.log10(peak * peak / mse)


def error_map(image: np.ndarray, reference: np.ndarray, mask: np.ndarray | None = None):
    """Per-pixel error relative to the reference's mean brightness:
    ``‖a − b‖₂(RGB) / mean‖b‖₂`` over the masked pixels; 0 outside the mask."""
    if mask is None:
        mask = coverage_mask(reference)
    a = np.asarray(image, dtype=np.float64)[..., :3]
    b = np.asarray(reference, dtype=np.float64)[..., :3]
    err = np.linalg.norm(np.nan_to_num(a - b, nan=np.inf), axis=-1)
    scale = float(np.linalg.norm(b[mask], axis=-1).mean()) if mask.any() else 0.0
    out = np.where(mask, err / max(scale, 1e-30), 0.0)
    return out


# Inferno-like colour ramp (black → purple → orange → pale yellow).
_RAMP = np.array([[0.0, 0.0, 0.02], [0.26, 0.04, 0.41], [0.58, 0.15, 0.40],
                  [0.87, 0.32, 0.23], [0.99, 0.64, 0.04], [0.99, 1.0, 0.64]])


def heatmap_rgb(values: np.ndarray, vmax: float, mask: np.ndarray | None = None) -> np.ndarray:
    """uint8 RGB (H, W, 3) of ``values / vmax`` through the ramp (≥ vmax saturates,
    NaN/Inf shows bright green); pixels outside ``mask`` are mid grey."""
    v = np.asarray(values, dtype=np.float64)
    bad = ~np.isfinite(v)
    t = np.clip(np.nan_to_num(v, nan=0.0, posinf=0.0) / max(vmax, 1e-30), 0.0, 1.0)
    x = t * (len(_RAMP) - 1)
    i = np.minimum(x.astype(np.int64), len(_RAMP) - 2)
    f = (x - i)[..., None]
    rgb = _RAMP[i] * (1.0 - f) + _RAMP[i + 1] * f
    rgb[bad] = (0.0, 1.0, 0.0)
    if mask is not None:
        rgb[~mask] = (0.35, 0.35, 0.35)
    return (np.clip(rgb, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def srgb_encode(linear: np.ndarray) -> np.ndarray:
    """The sRGB transfer function of linear values in [0, 1]."""
    x = np.clip(linear, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def exposure_for(reference: np.ndarray, percentile: float = 99.0) -> float:
    """A display scale mapping the reference's ``percentile`` brightness (masked
    pixels, max over RGB) to 0.9."""
    mask = coverage_mask(reference)
    px = np.asarray(reference)[..., :3][mask]
    if px.size == 0:
        return 1.0
    level = float(np.percentile(np.nan_to_num(px.max(axis=-1)), percentile))
    return 0.9 / level if level > 0.0 and np.isfinite(level) else 1.0


def display_rgb(image: np.ndarray, exposure: float,
                background=(0.18, 0.18, 0.18)) -> np.ndarray:
    """uint8 RGB for viewing: ``exposure × linear``, alpha over a grey, sRGB encoded."""
    img = np.nan_to_num(np.asarray(image, dtype=np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    rgb = img[..., :3] * exposure
    if img.shape[-1] > 3:
        a = np.clip(img[..., 3:4], 0.0, 1.0)
        rgb = rgb + (1.0 - a) * np.asarray(background)
    return (srgb_encode(rgb) * 255.0 + 0.5).astype(np.uint8)


def have_openimageio() -> bool:
    """Whether :func:`write_png` can write (OpenImageIO ships inside Blender 4.5+; the
    add-on falls back to Blender's image API without it)."""
    return oiio is not None


def write_png(path, rgb: np.ndarray):
    """Write uint8 RGB/RGBA (H, W, 3|4), top row first, as an 8-bit PNG with OpenImageIO
    (alpha as given: unassociated)."""
    px = np.ascontiguousarray(rgb, dtype=np.uint8)
    if px.ndim == 2:
        px = np.repeat(px[..., None], 3, axis=-1)
    h, w, c = px.shape
    if c not in (3, 4):
        raise ValueError(f"PNG needs 3 or 4 channels, got {c}")
    if oiio is None:
        raise RuntimeError("OpenImageIO is not available: write the PNG with Blender's "
                           "image API (addon/benchmark/operator.py)")
    out = oiio.ImageOutput.create(str(path))
    if out is None:
        raise OSError(f"cannot write {path}: {oiio.geterror()}")
    spec = oiio.ImageSpec(w, h, c, oiio.UINT8)
    spec.attribute("oiio:UnassociatedAlpha", 1)
    try:
        if not (out.open(str(path), spec) and out.write_image(px)):
            raise OSError(f"cannot write {path}: {out.geterror()}")
    finally:
        out.close()


# --------------------------------------------------------------------- Pareto


def pareto_frontier(times, errors) -> list[int]:
    """Indices of the non-dominated points, fastest first: a point is kept when no
    other point is at most as slow *and* at most as wrong while better in one of
    the two.  Non-finite points are never on the frontier."""
    t = np.asarray(times, dtype=np.float64)
    e = np.asarray(errors, dtype=np.float64)
    ok = np.isfinite(t) & np.isfinite(e)
    order = sorted(np.nonzero(ok)[0], key=lambda i: (t[i], e[i]))
    frontier, best = [], math.inf
    for i in order:
        if e[i] < best:
            frontier.append(int(i))
            best = e[i]
    return frontier


def fastest_meeting(rows, target: float, key: str = "error_ref"):
    """The row with the smallest ``frame_seconds`` whose ``key`` ≤ ``target``, or None."""
    best = fastest_candidates(rows, target, count=1, key=key)
    return best[0] if best else None


def fastest_candidates(rows, target: float, count: int = 3, within: float = 2.0,
                       key: str = "error_ref"):
    """Up to ``count`` rows meeting ``target`` (as :func:`fastest_meeting`), fastest first,
    whose ``frame_seconds`` is at most ``within`` times the fastest one's: the fixed
    methods worth timing again side by side, since one sweep's timings move with the
    machine's load."""
    ok = sorted((r for r in rows if r.get(key) is not None and np.isfinite(r[key])
                 and r[key] <= target and np.isfinite(r.get("frame_seconds", math.inf))),
                key=lambda r: r["frame_seconds"])
    return [r for r in ok if r["frame_seconds"] <= within * ok[0]["frame_seconds"]][:count]


# --------------------------------------------------------------------- SVG plot

_PALETTE = ["#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2",
            "#17becf", "#bcbd22", "#7f7f7f"]


def method_colours(method_ids) -> dict:
    """One colour per method id (stable: in the order given)."""
    out = {}
    for mid in method_ids:
        if mid not in out:
            out[mid] = _PALETTE[len(out) % len(_PALETTE)]
    return out


def _nice_log_ticks(lo: float, hi: float):
    a, b = math.floor(math.log10(lo)), math.ceil(math.log10(hi))
    ticks = []
    for p in range(a, b + 1):
        for m in (1, 2, 5):
            v = m * 10.0 ** p
            if lo <= v <= hi:
                ticks.append(v)
    return ticks or [lo, hi]


def _fmt_seconds(s: float) -> str:
    if s >= 1.0:
        return f"{s:g} s"
    if s >= 1e-3:
        return f"{s * 1e3:g} ms"
    return f"{s * 1e6:g} µs"


def speed_error_svg(rows, colours: dict | None = None, key: str = "error_ref",
                    width: int = 720, height: int = 440, title: str = "") -> str:
    """Inline SVG: per-frame time (log x) against error (linear y, in %), one colour per
    method, each point labelled with its budget, the Pareto frontier as a line.

    ``rows``: dicts with ``method``, ``label`` (short point label), ``frame_seconds``
    and ``key``.  Rows whose time or error is not finite are listed under the plot
    instead of drawn.
    """
    colours = colours or method_colours(r["method"] for r in rows)
    pts = [r for r in rows if r.get(key) is not None and np.isfinite(r[key])
           and np.isfinite(r.get("frame_seconds", math.nan)) and r["frame_seconds"] > 0]
    left, right, top, bottom = 70, 170, 30, 50
    pw, ph = width - left - right, height - top - bottom
    esc = html.escape
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
           f'viewBox="0 0 {width} {height}" font-family="sans-serif" font-size="11">',
           f'<rect x="0" y="0" width="{width}" height="{height}" fill="white"/>']
    if title:
        out.append(f'<text x="{left}" y="18" font-size="13" font-weight="bold">'
                   f'{esc(title)}</text>')
    if not pts:
        out.append(f'<text x="{left}" y="{top + ph / 2}">no finite measurements</text></svg>')
        return "\n".join(out)
    ts = [r["frame_seconds"] for r in pts]
    es = [100.0 * r[key] for r in pts]
    tlo, thi = min(ts) / 1.5, max(ts) * 1.5
    emax = max(es) * 1.1 if max(es) > 0 else 1.0

    def X(t):
        return left + pw * (math.log10(t) - math.log10(tlo)) / (math.log10(thi) - math.log10(tlo))

    def Y(e):
        return top + ph * (1.0 - e / emax)

    out.append(f'<rect x="{left}" y="{top}" width="{pw}" height="{ph}" fill="none" '
               f'stroke="#444"/>')
    for t in _nice_log_ticks(tlo, thi):
        x = X(t)
        out.append(f'<line x1="{x:.1f}" y1="{top}" x2="{x:.1f}" y2="{top + ph}" '
                   f'stroke="#ddd"/>')
        out.append(f'<text x="{x:.1f}" y="{top + ph + 15}" text-anchor="middle">'
                   f'{esc(_fmt_seconds(t))}</text>')
    step = 10 ** math.floor(math.log10(emax / 2)) if emax > 0 else 1
    for mult in (1, 2, 5, 10):
        if emax / (step * mult) <= 8:
            step *= mult
            break
    e = 0.0
    while e <= emax + 1e-12:
        y = Y(e)
        out.append(f'<line x1="{left}" y1="{y:.1f}" x2="{left + pw}" y2="{y:.1f}" '
                   f'stroke="#ddd"/>')
        out.append(f'<text x="{left - 6}" y="{y + 4:.1f}" text-anchor="end">{e:g} %</text>')
        e += step
    out.append(f'<text x="{left + pw / 2}" y="{height - 10}" text-anchor="middle">'
               'time per frame (log scale)</text>')
    out.append(f'<text x="16" y="{top + ph / 2}" text-anchor="middle" '
               f'transform="rotate(-90 16 {top + ph / 2})">'
               f'{"rel-L2 error vs " + ("REFERENCE" if key == "error_ref" else "Cycles")}'
               '</text>')
    front = pareto_frontier(ts, es)
    if len(front) > 1:
        path = " ".join(f"{X(ts[i]):.1f},{Y(es[i]):.1f}" for i in front)
        out.append(f'<polyline points="{path}" fill="none" stroke="#000" stroke-width="1.5" '
                   'stroke-dasharray="5,3"/>')
    for i, r in enumerate(pts):
        c = colours.get(r["method"], "#000")
        x, y = X(ts[i]), Y(es[i])
        ring = ' stroke="#000" stroke-width="1.5"' if i in front else ""
        out.append(f'<circle cx="{x:.1f}" cy="{y:.1f}" r="5" fill="{c}"{ring}>'
                   f'<title>{esc(r["method"])} {esc(str(r.get("label", "")))}: '
                   f'{esc(_fmt_seconds(ts[i]))}, {es[i]:.3g} %</title></circle>')
        if r.get("label"):
            out.append(f'<text x="{x + 7:.1f}" y="{y - 6:.1f}" font-size="9" fill="{c}">'
                       f'{esc(str(r["label"]))}</text>')
    ly = top + 6
    for mid, c in colours.items():
        if not any(r["method"] == mid for r in rows):
            continue
        missing = not any(r["method"] == mid for r in pts)
        out.append(f'<circle cx="{left + pw + 18}" cy="{ly}" r="5" fill="{c}"/>')
        out.append(f'<text x="{left + pw + 28}" y="{ly + 4}">{esc(mid)}'
                   f'{" (no finite point)" if missing else ""}</text>')
        ly += 18
    out.append(f'<line x1="{left + pw + 10}" y1="{ly}" x2="{left + pw + 26}" y2="{ly}" '
               'stroke="#000" stroke-dasharray="5,3"/>')
    out.append(f'<text x="{left + pw + 28}" y="{ly + 4}">Pareto frontier</text>')
    out.append("</svg>")
    return "\n".join(out)


# --------------------------------------------------------------------- HTML


def _fmt(v, spec=".3g", unit=""):
    if v is None:
        return "–"
    if isinstance(v, float) and not np.isfinite(v):
        return str(v)
    return f"{v:{spec}}{unit}"


def _bytes(n):
    if n is None:
        return "–"
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024.0


def _table(header, body_rows) -> str:
    h = "".join(f"<th>{html.escape(str(c))}</th>" for c in header)
    b = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in row) + "</tr>" for row in body_rows)
    return f"<table><thead><tr>{h}</tr></thead><tbody>{b}</tbody></table>"


_CSS = """body{font-family:sans-serif;margin:1.5em;max-width:1400px;color:#222}
h1{font-size:1.5em}h2{font-size:1.2em;margin-top:1.6em}
.grid{display:flex;flex-wrap:wrap;gap:10px}
figure{margin:0;border:1px solid #ccc;padding:4px;background:#fafafa}
figure.win{border:2px solid #2a2}
figcaption{font-size:12px;max-width:100%}
img{image-rendering:pixelated;display:block}
table{border-collapse:collapse;font-size:13px}
td,th{border:1px solid #ccc;padding:3px 7px;text-align:right}
th{background:#eee}td:first-child,th:first-child{text-align:left}
.bad{color:#b00;font-weight:bold}.ok{color:#070}.note{color:#555;font-size:12px}"""


def write_html(path, report: dict) -> pathlib.Path:
    """Write ``index.html`` from ``report`` (keys below); images are the PNG files
    already written next to it (relative names in the rows).

    ``report``: ``title``, ``scene`` (list of (name, value) lines), ``rows`` (one per
    method × budget: method, label, budget, frame_seconds, frame_times, error_ref,
    psnr_ref, error_cycles, psnr_cycles, image, heatmap, cycles_heatmap, notes),
    ``reference_image``, ``cycles_image`` (file names or None), ``heat_max``,
    ``methods`` (per method: id, label, precompute_seconds, storage_bytes, notes),
    ``targets`` (error levels for the "fastest meeting" summary), ``auto`` (rows of
    per-object choices: object, choice, reason), ``stability`` (see
    :func:`stability_html`), ``warnings``.
    """
    path = pathlib.Path(path)
    esc = html.escape
    rows = report["rows"]
    colours = method_colours([r["method"] for r in rows])
    has_cycles = any(r.get("error_cycles") is not None for r in rows)
    parts = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{esc(report['title'])}"
             f"</title><style>{_CSS}</style></head><body>",
             f"<h1>{esc(report['title'])}</h1>"]
    if report.get("scene"):
        parts.append("<p class='note'>" + " · ".join(
            f"{esc(str(k))}: {esc(str(v))}" for k, v in report["scene"]) + "</p>")
    # --- who wins where (first: the answer at a glance)
    targets = report.get("targets", [0.01, 0.02, 0.05, 0.1])
    winners = []
    for target in targets:
        best = fastest_meeting(rows, target)
        winners.append((target, best))
    win_ids = {id(b) for _, b in winners if b is not None}
    summary = []
    for target, best in winners:
        if best is None:
            summary.append(f"<li>error ≤ {target:.0%}: no method</li>")
        else:
            colour = colours[best["method"]]
            summary.append(f"<li>error ≤ {target:.0%}: <b style='color:{colour}'>"
                           f"{esc(best['method'])} {esc(str(best.get('label', '')))}</b> "
                           f"({_fmt_seconds(best['frame_seconds'])} per frame, "
                           f"{100 * best['error_ref']:.2f} %)</li>")
    parts.append("<h2>Fastest method for each error target (vs REFERENCE)</h2><ul>"
                 + "".join(summary) + "</ul>")
    # --- pictures
    parts.append("<h2>Images (top) and error against REFERENCE (bottom)</h2>")
    heat_max = report.get("heat_max", 0.2)
    parts.append(f"<p class='note'>Heat map: per-pixel ‖RGB error‖ / mean ‖REFERENCE‖, "
                 f"black = 0, pale yellow ≥ {heat_max:.0%}; grey = background (not measured)."
                 "</p><div class='grid'>")
    ref_img = report.get("reference_image")
    if ref_img:
        parts.append(f"<figure><img src='{esc(ref_img)}'><figcaption><b>REFERENCE</b>"
                     "</figcaption></figure>")
    if report.get("cycles_image"):
        parts.append(f"<figure><img src='{esc(report['cycles_image'])}'><figcaption>"
                     f"<b>Cycles</b> {esc(str(report.get('cycles_note', '')))}</figcaption>"
                     "</figure>")
    parts.append("</div><div class='grid'>")
    for r in rows:
        if r["method"] == "REFERENCE" or not r.get("image"):
            continue
        cls = " class='win'" if id(r) in win_ids else ""
        cap = (f"<b style='color:{colours[r['method']]}'>{esc(r['method'])}</b> "
               f"{esc(str(r.get('label', '')))}<br>{_fmt_seconds(r['frame_seconds'])}"
               if np.isfinite(r.get("frame_seconds", math.nan)) else esc(r["method"]))
        cap += f", {_fmt(100 * r['error_ref'], '.2f', ' %')}" if r.get("error_ref") is not None \
            else ""
        heat = f"<img src='{esc(r['heatmap'])}'>" if r.get("heatmap") else ""
        parts.append(f"<figure{cls}><img src='{esc(r['image'])}'>{heat}<figcaption>{cap}"
                     "</figcaption></figure>")
    parts.append("</div>")
    # --- plot
    parts.append("<h2>Speed against error</h2>")
    parts.append(speed_error_svg(rows, colours, "error_ref",
                                 title="Per-frame time vs rel-L2 error against REFERENCE"))
    if has_cycles:
        parts.append(speed_error_svg(rows, colours, "error_cycles",
                                     title="Per-frame time vs rel-L2 error against Cycles"))
    # --- numbers
    parts.append("<h2>Numbers</h2>")
    front = set(pareto_frontier([r["frame_seconds"] for r in rows],
                                [r.get("error_ref", math.nan) if r.get("error_ref") is not None
                                 else math.nan for r in rows]))
    header = ["method", "budget", "frame (median)", "repeats", "rel-L2 vs REF", "PSNR vs REF"]
    if has_cycles:
        header += ["rel-L2 vs Cycles", "PSNR vs Cycles"]
    header += ["Pareto", "notes"]
    body = []
    for i, r in enumerate(rows):
        line = [f"<span style='color:{colours[r['method']]}'>■</span> {esc(r['method'])}",
                esc(str(r.get("budget", "") or "")),
                esc(_fmt_seconds(r["frame_seconds"])) if np.isfinite(
                    r.get("frame_seconds", math.nan)) else "–",
                str(len(r.get("frame_times", []))),
                _fmt(100 * r["error_ref"] if r.get("error_ref") is not None else None,
                     ".3f", " %"),
                _fmt(r.get("psnr_ref"), ".2f", " dB")]
        if has_cycles:
            line += [_fmt(100 * r["error_cycles"] if r.get("error_cycles") is not None
                          else None, ".3f", " %"), _fmt(r.get("psnr_cycles"), ".2f", " dB")]
        line += ["★" if i in front else "", esc(r.get("notes", ""))]
        body.append(line)
    parts.append(_table(header, body))
    # --- precompute and storage
    if report.get("methods"):
        parts.append("<h2>Precompute cost and storage per method</h2>")
        parts.append(_table(
            ["method", "label", "precompute", "storage", "notes"],
            [[esc(m["id"]), esc(m.get("label", "")), _fmt(m.get("precompute_seconds"), ".3g",
                                                            " s"),
              _bytes(m.get("storage_bytes")), esc(m.get("notes", ""))]
             for m in report["methods"]]))
    # --- AUTO
    if report.get("auto"):
        parts.append("<h2>AUTO: representation chosen per object</h2>")
        parts.append(_table(["object", "choice", "measured error", "why"],
                            [[esc(a["object"]), esc(a["choice"]),
                              _fmt(100 * a["error"] if a.get("error") is not None else None,
                                   ".2f", " %"), esc(a.get("reason", ""))]
                             for a in report["auto"]]))
    check = report.get("auto_check")
    if check:
        verdict = "faster" if check["ratio"] > 1.0 else "not faster"
        parts.append(
            f"<p>AUTO ({_fmt(100 * check['auto_error'], '.2f', ' %')} against REFERENCE) "
            f"against the fastest fixed method within {100 * check['target']:.3g} %, "
            f"{esc(check['fixed'])} ({_fmt(100 * check['fixed_error'], '.2f', ' %')}), "
            + (f"of {esc(', '.join(check['candidates']))} (the sweep's fastest within 2× of "
               f"each other), " if len(check.get("candidates", ())) > 1 else "")
            + f"timed on {check['rounds']} interleaved relit frames each: "
            f"{1e3 * check['auto_seconds']:.2f} ms against {1e3 * check['fixed_seconds']:.2f} ms "
            f"(median), {check['ratio']:.2f}× — AUTO is {verdict}.</p>")
    if report.get("stability"):
        parts.append("<h2>Stability: hard cases × methods</h2>")
        parts.append(stability_html(report["stability"]))
    if report.get("warnings"):
        parts.append("<h2>Warnings</h2><ul>" + "".join(
            f"<li>{esc(w)}</li>" for w in report["warnings"]) + "</ul>")
    parts.append("</body></html>")
    path.write_text("\n".join(parts), encoding="utf-8")
    return path


def stability_html(table: dict) -> str:
    """HTML of a stability table: ``table = {"methods": [...], "cases": [{"name",
    "description", "cells": {method: {"finite", "error", "message", "bound"}}}]}``; an
    error above its bound is marked."""
    esc = html.escape
    body = []
    for case in table["cases"]:
        line = [f"<b>{esc(case['name'])}</b><br><span class='note'>"
                f"{esc(case.get('description', ''))}</span>"]
        for mid in table["methods"]:
            cell = case["cells"].get(mid)
            if cell is None:
                line.append("<span class='note'>n/a</span>")
                continue
            fin = ("<span class='ok'>finite</span>" if cell["finite"]
                   else "<span class='bad'>NON-FINITE</span>")
            err = cell.get("error")
            text = fin + (f" / {100 * err:.3g} %" if err is not None and np.isfinite(err)
                          else " / –")
            bound = cell.get("bound")
            if bound is not None:
                over = err is None or not np.isfinite(err) or err > bound
                text += (f" <span class='{'bad' if over else 'note'}'>"
                         f"({'ABOVE its ' if over else ''}bound {100 * bound:.3g} %)</span>")
            if cell.get("message"):
                text += f"<br><span class='note'>{esc(cell['message'][:120])}</span>"
            line.append(text)
        body.append(line)
    return _table(["case"] + list(table["methods"]), body)
