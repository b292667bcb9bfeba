"""What the mesh routes can answer besides JSON: the region as a GLB with UVs, a picture of
its map (SVG or PNG), sites as a PLY point cloud; and the choice among them from ``Accept``
or ``params.output``."""

from __future__ import annotations

from enum import StrEnum

from ..problems import Problem


class Output(StrEnum):
    """The answer's form, by its ``params.output`` name (in the order that settles ties)."""

    JSON = "json"
    GLB = "glb"
    SVG = "svg"
    PNG = "png"
    PLY = "ply"
    FACE_IDS = "face_ids"
    BARYCENTRIC = "barycentric"

    @property
    def media_type(self) -> str:
        return _MEDIA_TYPES[self]

    @property
    def binary(self) -> bool:
        """Whether the form is bytes rather than text."""
        return self in (Output.GLB, Output.PNG, Output.PLY, Output.FACE_IDS, Output.BARYCENTRIC)


_MEDIA_TYPES = {
    Output.JSON: "application/json",
    Output.GLB: "model/gltf-binary",
    Output.SVG: "image/svg+xml",
    Output.PNG: "image/png",
    # No PLY media type is registered; this is the one in common use.
    Output.PLY: "application/ply",
    # Look-up images: a little-endian array behind a 16-byte header (service.outputs.lookup).
    Output.FACE_IDS: "application/octet-stream",
    Output.BARYCENTRIC: "application/octet-stream",
}


def choose_output(
    accept: str | None, requested: str | None, allowed: tuple[Output, ...] = tuple(Output)
) -> Output:
    """The answer's form among ``allowed``: ``params.output`` when given, else the one the
    ``Accept`` header prefers (RFC 9110: each form takes the quality of the most specific
    range that matches it; ties go to the range listed first, then to the order of
    ``allowed``); JSON when there is no header.

    Raises
    ------
    Problem
        406 when ``Accept`` allows none of the forms.
    """
    if requested is not None:
        if Output(requested) not in allowed:
            known = ", ".join(output.value for output in allowed)
            raise Problem(422, f"params.output: one of {known}", "invalid-request", "params.output")
        return Output(requested)
    if accept is None or not accept.strip():
        return Output.JSON
    ranges = [_media_range(item) for item in accept.split(",") if item.strip()]
    scored = []
    for order, output in enumerate(allowed):
        kind, subtype = output.media_type.split("/")
        matches = [
            (specificity, -position, quality)
            for position, (range_kind, range_subtype, quality) in enumerate(ranges)
            if (specificity := _specificity(range_kind, range_subtype, kind, subtype)) >= 0
        ]
        if matches:
            specificity, position, quality = max(matches)
            if quality > 0:
                scored.append((quality, position, -order, output))
    if not scored:
        produced = ", ".join(output.media_type for output in allowed)
        raise Problem(
            406,
            f"Accept: {accept.strip()!r} allows none of {produced} (or set params.output)",
            "not-acceptable",
            "Accept",
        )
    return max(scored)[-1]


def _media_range(item: str) -> tuple[str, str, float]:
    """``type``, ``subtype`` and quality of one element of an Accept header."""
    media_range, *parameters = (part.strip() for part in item.split(";"))
    kind, _, subtype = media_range.lower().partition("/")
    quality = 1.0
    for parameter in parameters:
        name, _, value = parameter.partition("=")
        if name.strip().lower() == "q":
            try:
                quality = min(max(float(value), 0.0), 1.0)
            except ValueError:
                quality = 0.0
    return kind, subtype or "*", quality


def _specificity(range_kind: str, range_subtype: str, kind: str, subtype: str) -> int:
    """2 for an exact match, 1 for ``type/*``, 0 for ``*/*``, -1 for no match."""
    if range_kind == kind and range_subtype == subtype:
        return 2
    if range_kind == kind and range_subtype == "*":
        return 1
    return 0 if range_kind == "*" and range_subtype == "*" else -1
