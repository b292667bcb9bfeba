"""A :class:`.picture.Picture` drawn as SVG (vector, with a decimated fill on large regions)
or PNG (Pillow: the raster, lines and text)."""

from __future__ import annotations

import io
from xml.sax.saxutils import escape

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from transforms.raster import paint_segments

from .colours import STEPS, hex_colour, hex_of, palette
from .picture import (
    BOUNDARY,
    COLOURS,
    CURVE_KEY,
    FILL,
    GRID_KEY,
    OUTLINE,
    SEAM_COLOUR,
    SINGULAR_COLOUR,
    SITES_COLOUR,
    SITES_KEY,
    STROKES_COLOUR,
    SVG_SITES,
    Picture,
)

#: The colour bar's width, pixels (in the legend's column).
BAR_WIDTH = 220
#: Boundary edges drawn as vector lines up to this many (beyond: painted into the fill).
VECTOR_BOUNDARY = 100_000
#: Cells of the SVG's decimated fill, in canvas pixels.
FILL_CELL = 2.0
_FONT = 'font-family="DejaVu Sans, Verdana, sans-serif"'


def to_svg(picture: Picture) -> bytes:
    """The picture as a standalone SVG document."""
    p = picture
    left, top, right, bottom = p.plot
    parts = [
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{p.width}" height="{p.height}" '
        f'viewBox="0 0 {p.width} {p.height}">',
        f"<title>{escape(p.caption[0])}</title>",
        f'<rect width="{p.width}" height="{p.height}" fill="#ffffff"/>',
        f'<g id="map" clip-path="url(#plot)"><clipPath id="plot"><rect x="{left}" y="{top}" '
        f'width="{right - left}" height="{bottom - top}"/></clipPath>',
    ]
    vector_boundary = len(p.boundary) <= VECTOR_BOUNDARY
    if p.vector:
        parts += _svg_triangles(p)
    else:
        parts += _decimated_fill(p, include_boundary=not vector_boundary)
    if len(p.grid):
        parts.append(
            f'<path class="grid" fill="none" stroke="{p.grid_colour}" stroke-width="0.8" '
            f'd="{_rows(p.grid.reshape(-1, 4), "M%.1f %.1fL%.1f %.1f")}"/>'
        )
    marks, labels = p.marks()
    for label in np.unique(labels):
        parts.append(
            f'<path class="marks label-{label}" fill="{COLOURS[int(label)]}" '
            f'd="{_rows(marks[labels == label] - 2.0, "M%.1f %.1fh4v4h-4Z")}"/>'
        )
    if vector_boundary and len(p.boundary):
        parts.append(
            f'<path class="boundary" fill="none" stroke="{COLOURS[BOUNDARY]}" '
            f'stroke-width="1.2" d="{_rows(p.boundary.reshape(-1, 4), "M%.1f %.1fL%.1f %.1f")}"/>'
        )
    for column in p.seam_columns:
        parts.append(
            f'<line class="seam" x1="{column:.1f}" y1="{top}" x2="{column:.1f}" y2="{bottom}" '
            f'stroke="{SEAM_COLOUR}" stroke-width="2" stroke-dasharray="8 5"/>'
        )
    for row, name in p.singular_rows:
        parts.append(
            f'<line class="singular {name}" x1="{left}" y1="{row:.1f}" x2="{right}" '
            f'y2="{row:.1f}" stroke="{SINGULAR_COLOUR}" stroke-width="2" '
            f'stroke-dasharray="3 4"/>'
        )
    if len(p.sites):  # under the zones' names
        shown = p.sites[:SVG_SITES] - 1.0
        parts.append(
            f'<path class="sites" fill="{SITES_COLOUR}" d="{_rows(shown, "M%.1f %.1fh2v2h-2Z")}"/>'
        )
    if len(p.strokes):
        segments = p.strokes[:SVG_SITES].reshape(-1, 4)
        parts.append(
            f'<path class="growth" fill="none" stroke="{STROKES_COLOUR}" stroke-width="1" '
            f'd="{_rows(segments, "M%.1f %.1fL%.1f %.1f")}"/>'
        )
    parts += _svg_overlays(p)
    parts.append("</g>")
    parts += _svg_frame(p)
    parts.append("</svg>")
    return "\n".join(parts).encode()


def _svg_triangles(p: Picture) -> list[str]:
    """The triangles one by one, a path for each colour: the flags' labels, or the steps of
    a measure's colours (each stroked in its own colour, so that no hairline shows between
    neighbours)."""
    parts, filled = [], ~p.wrapping
    keys, colours = _keys(p, p.labels, np.arange(len(p.labels)))
    for key in np.unique(keys[filled]):
        corners = p.corners[filled & (keys == key)].reshape(-1, 6)
        stroke = COLOURS[OUTLINE] if key == FILL else colours[int(key)]
        parts.append(
            f'<path class="triangles {_kind(key)}" fill="{colours[int(key)]}" '
            f'stroke="{stroke}" stroke-width="0.5" stroke-linejoin="round" '
            f'd="{_rows(corners, "M%.1f %.1fL%.1f %.1fL%.1f %.1fZ")}"/>'
        )
    return parts


#: Keys above this are colours of a measure (``COLOURED + k`` for the k-th colour).
COLOURED = 16


def _keys(p: Picture, labels: np.ndarray, ids: np.ndarray) -> tuple[np.ndarray, dict]:
    """The key of each pixel (or triangle) of ``labels`` holding triangle ``ids`` (-1:
    none): its label, or, on a picture coloured by a measure, ``COLOURED`` plus its colour's
    rank where the label is the plain fill; and each key's colour."""
    keys = labels.astype(np.int32)
    colours = dict(COLOURS)
    if p.face_colours is None:
        return keys, colours
    rgb = p.face_colours.astype(np.uint32)
    packed = (rgb[:, 0] << 16) | (rgb[:, 1] << 8) | rgb[:, 2]  # one number a colour: fast
    values, rank = np.unique(packed, return_inverse=True)
    distinct = np.stack([values >> 16, (values >> 8) & 255, values & 255], axis=1)
    coloured = (ids >= 0) & (labels <= FILL)
    keys[coloured] = COLOURED + rank.ravel()[ids[coloured]]
    colours.update({COLOURED + k: hex_of(rgb) for k, rgb in enumerate(distinct)})
    return keys, colours


def _kind(key: int) -> str:
    return f"colour-{key - COLOURED}" if key >= COLOURED else f"label-{key}"


def _svg_overlays(p: Picture) -> list[str]:
    """The zones (filled, the holes left open) and the curves, each labelled."""
    parts = []
    for overlay in p.overlays:
        colour = overlay.colour
        if overlay.closed:
            d = "".join("M" + _rows(ring, "%.1f %.1fL")[:-1] + "Z" for ring in overlay.rings)
            style = f'fill="{colour}" fill-opacity="0.3" fill-rule="evenodd"'
            kind = "zone"
        else:
            d = "".join("M" + _rows(ring, "%.1f %.1fL")[:-1] for ring in overlay.rings)
            style, kind = 'fill="none"', "curve"
        x, y = overlay.anchor
        parts.append(
            f'<g class="{kind}"><path {style} stroke="{colour}" stroke-width="2" '
            f'stroke-linejoin="round" d="{d}"/><text x="{x:.1f}" y="{y:.1f}" '
            f'text-anchor="middle" {_FONT} font-size="13" font-weight="bold" fill="{colour}" '
            f'stroke="#ffffff" stroke-width="3" paint-order="stroke">'
            f"{escape(overlay.name)}</text>{_svg_label(overlay)}</g>"
        )
    return parts


#: How far below a zone's name its label line goes, pixels.
LABEL_DROP = 15


def _svg_label(overlay) -> str:
    """The line under an overlay's name, when it has one."""
    if overlay.label is None:
        return ""
    x, y = overlay.anchor
    return (
        f'<text x="{x:.1f}" y="{y + LABEL_DROP:.1f}" text-anchor="middle" {_FONT} '
        f'font-size="12" fill="{overlay.colour}" stroke="#ffffff" stroke-width="3" '
        f'paint-order="stroke">{escape(overlay.label)}</text>'
    )


def _decimated_fill(p: Picture, include_boundary: bool) -> list[str]:
    """The fill as horizontal runs of equal colour on a grid of ``FILL_CELL`` pixels: the
    labels', or a measure's colour cell by cell (the triangle holding the cell's centre).
    At most one run a cell: the SVG's fill is bounded by the canvas, whatever the region."""
    labels = p.raster(1.0 / FILL_CELL, include_boundary=include_boundary)
    ids = p.face_ids(1.0 / FILL_CELL) if p.face_colours is not None else None
    image, colours = _keys(p, labels, ids if ids is not None else np.full(labels.shape, -1))
    left, top = p.plot[0], p.plot[1]
    parts = []
    for label in np.unique(image[image > 0]):
        mask = np.zeros((image.shape[0], image.shape[1] + 2), dtype=np.int8)
        mask[:, 1:-1] = image == label
        change = np.diff(mask, axis=1)
        rows, starts = np.nonzero(change == 1)
        _, stops = np.nonzero(change == -1)  # same rows, in the same order
        runs = np.stack(
            [
                left + starts * FILL_CELL,
                top + rows * FILL_CELL,
                (stops - starts) * FILL_CELL,
                np.full(len(rows), FILL_CELL),
                -(stops - starts) * FILL_CELL,
            ],
            axis=1,
        )
        parts.append(
            f'<path class="fill {_kind(label)}" fill="{colours[int(label)]}" '
            'shape-rendering="crispEdges" '
            f'd="{_rows(runs, "M%.1f %.1fh%.1fv%.1fh%.1fZ")}"/>'
        )
    return parts


def _svg_frame(p: Picture) -> list[str]:
    """Axes, ticks, legend and caption."""
    left, top, right, bottom = p.plot
    text = f'{_FONT} font-size="12" fill="#222222"'
    parts = [
        f'<rect x="{left}" y="{top}" width="{right - left}" height="{bottom - top}" '
        'fill="none" stroke="#444444"/>',
        '<g class="axes">',
    ]
    for column, label in p.x_ticks:
        parts.append(
            f'<line x1="{column:.1f}" y1="{bottom}" x2="{column:.1f}" y2="{bottom + 5}" '
            f'stroke="#444444"/><text x="{column:.1f}" y="{bottom + 18}" text-anchor="middle" '
            f"{text}>{label}</text>"
        )
    for row, label in p.y_ticks:
        parts.append(
            f'<line x1="{left - 5}" y1="{row:.1f}" x2="{left}" y2="{row:.1f}" stroke="#444444"/>'
            f'<text x="{left - 8}" y="{row + 4:.1f}" text-anchor="end" {text}>{label}</text>'
        )
    parts.append(
        f'<text x="{(left + right) / 2:.1f}" y="{bottom + 33}" text-anchor="middle" {text}>'
        f"{p.x_title}</text>"
        f'<text x="{left}" y="{top - 10}" text-anchor="start" {text}>{p.y_title}</text>'
    )
    parts.append("</g>")
    x, y = p.plot[2] + 20, p.plot[1]
    parts.append('<g class="legend">')
    for i, (label, colour, words) in enumerate(p.legend):
        row = y + 20 * i
        if label in (CURVE_KEY, GRID_KEY):
            parts.append(
                f'<line x1="{x}" y1="{row + 6}" x2="{x + 14}" y2="{row + 6}" stroke="{colour}" '
                'stroke-width="2"/>'
            )
        elif label == SITES_KEY:
            parts.append(f'<rect x="{x + 5}" y="{row + 4}" width="4" height="4" fill="{colour}"/>')
        elif label < 0:  # a line: the seam or the singular points
            parts.append(
                f'<line x1="{x}" y1="{row + 6}" x2="{x + 14}" y2="{row + 6}" stroke="{colour}" '
                'stroke-width="2" stroke-dasharray="4 2"/>'
            )
        else:
            parts.append(
                f'<rect x="{x}" y="{row}" width="14" height="12" fill="{colour}" '
                'stroke="#444444" stroke-width="0.5"/>'
            )
        parts.append(f'<text x="{x + 20}" y="{row + 11}" {text}>{escape(words)}</text>')
    parts.append("</g>")
    if p.colour_bar is not None:
        parts += _svg_colour_bar(p)
    for i, line in enumerate(p.caption):
        parts.append(
            f'<text class="caption" x="{p.plot[0]}" y="{caption_row(p, i)}" {text}>'
            f"{escape(line)}</text>"
        )
    return parts


#: The caption's lines: this far apart, the last this far above the canvas's bottom (pixels).
CAPTION_LEADING, CAPTION_BOTTOM = 15, 12


def caption_row(p: Picture, i: int) -> int:
    """The baseline of the caption's ``i``-th line: the lines end at the canvas's foot."""
    return p.height - CAPTION_BOTTOM - CAPTION_LEADING * (len(p.caption) - 1 - i)


def _rows(values: np.ndarray, fmt: str) -> str:
    """Every row of ``values`` through ``fmt``, joined."""
    out = io.StringIO()
    np.savetxt(
        out, np.asarray(values, dtype=np.float64).reshape(len(values), -1), fmt=fmt, newline=""
    )
    return out.getvalue()


def to_png(picture: Picture) -> bytes:
    """The picture as a PNG image of ``width`` x ``height`` pixels."""
    p = picture
    left, top, right, bottom = p.plot
    canvas = Image.new("RGB", (p.width, p.height), "#ffffff")
    canvas.paste(Image.fromarray(_png_fill(p), "RGB"), (left, top))
    font = ImageFont.load_default(size=13)
    if len(p.sites):
        canvas = _png_sites(canvas, p)
    if len(p.strokes):
        canvas = _png_strokes(canvas, p)
    if p.overlays:
        canvas = _png_overlays(canvas, p, font)
    draw = ImageDraw.Draw(canvas)
    for column in p.seam_columns:
        _dashed(draw, (column, top), (column, bottom), SEAM_COLOUR, 2, 8, 5)
    for row, _ in p.singular_rows:
        _dashed(draw, (left, row), (right, row), SINGULAR_COLOUR, 2, 3, 4)
    draw.rectangle((left, top, right, bottom), outline="#444444")
    for column, label in p.x_ticks:
        draw.line((column, bottom, column, bottom + 5), fill="#444444")
        draw.text((column, bottom + 8), label, fill="#222222", font=font, anchor="mt")
    for row, label in p.y_ticks:
        draw.line((left - 5, row, left, row), fill="#444444")
        draw.text((left - 8, row), label, fill="#222222", font=font, anchor="rm")
    draw.text(((left + right) / 2, bottom + 24), p.x_title, fill="#222222", font=font, anchor="mt")
    draw.text((left, top - 8), p.y_title, fill="#222222", font=font, anchor="ls")
    _png_legend(draw, p, font)
    if p.colour_bar is not None:
        _png_colour_bar(canvas, draw, p, font)
    for i, line in enumerate(p.caption):
        draw.text((left, caption_row(p, i)), line, fill="#222222", font=font, anchor="ls")
    out = io.BytesIO()
    canvas.save(out, format="PNG", optimize=False, compress_level=6)
    return out.getvalue()


def _png_fill(p: Picture) -> np.ndarray:
    """(h, w, 3) uint8: the plotting box's raster in the labels' colours, or, on a picture
    coloured by a measure, each pixel in its triangle's colour, flags on top."""
    colours = np.zeros((256, 3), dtype=np.uint8)
    for label, colour in COLOURS.items():
        colours[label] = _rgb(colour)
    labels = p.raster(1.0)
    fill = colours[labels]
    if p.face_colours is not None:
        ids = p.face_ids()
        coloured = (ids >= 0) & (labels <= FILL)
        fill[coloured] = p.face_colours[ids[coloured]]
    if len(p.grid):  # over the fill, under the flags and the boundary
        lines = np.zeros(labels.shape, dtype=np.uint8)
        paint_segments(lines, p.grid - np.array(p.plot[:2], dtype=np.float64), 1)
        fill[(lines > 0) & (labels <= OUTLINE)] = _rgb(p.grid_colour)
    return fill


def _png_sites(canvas: Image.Image, p: Picture) -> Image.Image:
    """The canvas with the sites: 2 x 2 pixels each, inside the plot (under the zones'
    names, drawn after)."""
    left, top, right, bottom = p.plot
    spots = np.floor(p.sites - 0.5).astype(np.int64)
    inside = np.all((spots >= [left, top]) & (spots < [right - 1, bottom - 1]), axis=1)
    pixels = np.asarray(canvas).copy()
    for dx, dy in ((0, 0), (1, 0), (0, 1), (1, 1)):
        pixels[spots[inside, 1] + dy, spots[inside, 0] + dx] = _rgb(SITES_COLOUR)
    return Image.fromarray(pixels, "RGB")


def _png_strokes(canvas: Image.Image, p: Picture) -> Image.Image:
    """The canvas with each site's stroke, one pixel wide, inside the plot."""
    left, top, right, bottom = p.plot
    painted = np.zeros((bottom - top, right - left), dtype=np.uint8)
    paint_segments(painted, p.strokes - np.array([left, top], dtype=np.float64), 1)
    pixels = np.asarray(canvas).copy()
    pixels[top:bottom, left:right][painted > 0] = _rgb(STROKES_COLOUR)
    return Image.fromarray(pixels, "RGB")


def _png_legend(draw: ImageDraw.ImageDraw, p: Picture, font) -> None:
    x, y = p.plot[2] + 20, p.plot[1]
    for i, (label, colour, words) in enumerate(p.legend):
        row = y + 20 * i
        if label == GRID_KEY:  # a light line on the legend's white: outlined
            draw.rectangle((x, row + 3, x + 14, row + 9), fill="#9a9a9a")
            draw.line((x, row + 6, x + 14, row + 6), fill=colour, width=2)
        elif label == CURVE_KEY:
            draw.line((x, row + 6, x + 14, row + 6), fill=colour, width=2)
        elif label == SITES_KEY:
            draw.rectangle((x + 5, row + 4, x + 8, row + 7), fill=colour)
        elif label < 0:
            _dashed(draw, (x, row + 6), (x + 14, row + 6), colour, 2, 4, 2)
        else:
            draw.rectangle((x, row, x + 14, row + 12), fill=colour, outline="#444444")
        # The default font has no superscripts.
        words = words.replace("²", "2")
        draw.text((x + 20, row + 6), words, fill="#222222", font=font, anchor="lm")


def _bar_box(p: Picture) -> tuple[int, int, int, int]:
    """Where the colour bar goes: under the legend, (left, top, right, bottom)."""
    x, y = p.plot[2] + 20, p.plot[1] + 20 * len(p.legend) + 30
    return x, y, x + BAR_WIDTH, y + 14


def _bar_ticks(p: Picture) -> list[tuple[float, str, bool]]:
    """(x, text, below) of the bar's labels: its ends, and its p50 and p95 marks."""
    bar = p.colour_bar
    left, _, right, _ = _bar_box(p)
    at = lambda value: left + float(bar.position(np.array([value]))[0]) * (right - left)  # noqa: E731
    return [
        (left, f"{bar.low:.3g}", True),
        (right, f"{bar.high:.3g}", True),
        (at(bar.p50), f"p50 {bar.p50:.3g}", False),
        (at(bar.p95), f"p95 {bar.p95:.3g}", False),
    ]


def _png_colour_bar(canvas: Image.Image, draw: ImageDraw.ImageDraw, p: Picture, font) -> None:
    left, top, right, bottom = _bar_box(p)
    steps = (np.arange(right - left) * STEPS // (right - left)).astype(np.int64)
    strip = np.repeat(palette(p.colour_bar.colour_map)[steps][None], bottom - top, axis=0)
    canvas.paste(Image.fromarray(strip, "RGB"), (left, top))
    draw.rectangle((left, top, right, bottom), outline="#444444")
    draw.text((left, top - 18), p.colour_bar.title, fill="#222222", font=font, anchor="ls")
    for x, words, below in _bar_ticks(p):
        if below:
            draw.text((x, bottom + 4), words, fill="#222222", font=font, anchor="mt")
        else:
            draw.line((x, top - 4, x, bottom), fill="#222222", width=1)
            draw.text((x, top - 5), words, fill="#222222", font=font, anchor="ms")


def _svg_colour_bar(p: Picture) -> list[str]:
    left, top, right, bottom = _bar_box(p)
    text = f'{_FONT} font-size="12" fill="#222222"'
    stops = "".join(
        f'<stop offset="{k / 16:.4f}" '
        f'stop-color="{hex_colour(min(k * STEPS // 16, STEPS - 1), p.colour_bar.colour_map)}"/>'
        for k in range(17)
    )
    parts = [
        f'<g class="colour-bar"><defs><linearGradient id="bar">{stops}</linearGradient></defs>',
        f'<rect x="{left}" y="{top}" width="{right - left}" height="{bottom - top}" '
        'fill="url(#bar)" stroke="#444444" stroke-width="0.5"/>',
        f'<text x="{left}" y="{top - 18}" {text}>{escape(p.colour_bar.title)}</text>',
    ]
    for x, words, below in _bar_ticks(p):
        if below:
            parts.append(
                f'<text x="{x:.1f}" y="{bottom + 15}" text-anchor="middle" {text}>{words}</text>'
            )
        else:
            parts.append(
                f'<line x1="{x:.1f}" y1="{top - 4}" x2="{x:.1f}" y2="{bottom}" '
                f'stroke="#222222"/><text x="{x:.1f}" y="{top - 6}" text-anchor="middle" '
                f"{text}>{words}</text>"
            )
    parts.append("</g>")
    return parts


def _png_overlays(canvas: Image.Image, p: Picture, font) -> Image.Image:
    """The canvas with the zones filled (30 % opaque, the holes left open), their outlines,
    the curves and the names, clipped to the plot."""
    left, top, right, bottom = p.plot
    size, origin = (right - left, bottom - top), np.array([left, top], dtype=np.float64)
    layer = Image.new("RGBA", size, (0, 0, 0, 0))
    draw = ImageDraw.Draw(layer)
    for overlay in p.overlays:
        if overlay.closed:
            zone = Image.new("RGBA", size, (0, 0, 0, 0))
            fill = ImageDraw.Draw(zone)
            fill.polygon(_points(overlay.rings[0] - origin), fill=(*_rgb(overlay.colour), 77))
            for hole in overlay.rings[1:]:
                fill.polygon(_points(hole - origin), fill=(0, 0, 0, 0))
            layer.alpha_composite(zone)
    for overlay in p.overlays:
        for ring in overlay.rings:
            points = _points(ring - origin)
            draw.line(points + points[:1] * overlay.closed, fill=overlay.colour, width=2)
        draw.text(
            tuple(np.asarray(overlay.anchor) - origin),
            overlay.name,
            fill=overlay.colour,
            font=font,
            anchor="mm",
            stroke_width=2,
            stroke_fill="#ffffff",
        )
        if overlay.label is not None:
            # The default font has no superscripts.
            draw.text(
                tuple(np.asarray(overlay.anchor) - origin + (0.0, LABEL_DROP)),
                overlay.label.replace("²", "2"),
                fill=overlay.colour,
                font=font,
                anchor="mm",
                stroke_width=2,
                stroke_fill="#ffffff",
            )
    canvas = canvas.convert("RGBA")
    canvas.alpha_composite(layer, (left, top))
    return canvas.convert("RGB")


def _points(ring: np.ndarray) -> list[tuple[float, float]]:
    return [(float(x), float(y)) for x, y in ring]


def _dashed(draw, start, end, colour, width, dash, gap) -> None:
    """A dashed straight line (a few dozen dashes at most)."""
    (x0, y0), (x1, y1) = start, end
    length = float(np.hypot(x1 - x0, y1 - y0))
    if length == 0:
        return
    for t in np.arange(0.0, length, dash + gap):
        a, b = t / length, min(t + dash, length) / length
        draw.line(
            (x0 + (x1 - x0) * a, y0 + (y1 - y0) * a, x0 + (x1 - x0) * b, y0 + (y1 - y0) * b),
            fill=colour,
            width=width,
        )


def _rgb(colour: str) -> tuple[int, int, int]:
    return tuple(int(colour[i : i + 2], 16) for i in (1, 3, 5))
