"""The forms of an answer (:class:`Output`, the one vocabulary of them) and the encoders of
those besides JSON: the region as a GLB with UVs (:mod:`.glb`), a picture of its map as SVG
or PNG (:mod:`.picture`, :mod:`.draw`, :mod:`.colours`), the look-up images (:mod:`.lookup`),
the JSON answer's arrays as Arrow columns (:mod:`.arrow`).
Which form a request gets is the HTTP edge's choice (:func:`service.forms.choose_output`)."""

from __future__ import annotations

from enum import StrEnum


class Output(StrEnum):
    """The answer's form, by its ``params.output`` name (in the order that settles ties)."""

    JSON = "json"
    GLB = "glb"
    SVG = "svg"
    PNG = "png"
    PLY = "ply"
    USD = "usd"
    FACE_IDS = "face_ids"
    BARYCENTRIC = "barycentric"
    ARROW = "arrow"

    @property
    def media_type(self) -> str:
        return _MEDIA_TYPES[self]

    @property
    def suffix(self) -> str:
        """The file name's extension of the form (``.usda`` for the USD text stage)."""
        return ".usda" if self is Output.USD else f".{self.value}"

    @property
    def binary(self) -> bool:
        """Whether the form is bytes rather than text."""
        return self not in (Output.JSON, Output.SVG, Output.USD)  # the text forms


_MEDIA_TYPES = {
    Output.JSON: "application/json",
    Output.GLB: "model/gltf-binary",
    Output.SVG: "image/svg+xml",
    Output.PNG: "image/png",
    # No PLY media type is registered; this is the one in common use.
    Output.PLY: "application/ply",
    # USD's text form (Pixar's registration with IANA).
    Output.USD: "model/vnd.usda",
    # Look-up images: a little-endian array behind a 16-byte header (service.outputs.lookup).
    Output.FACE_IDS: "application/octet-stream",
    Output.BARYCENTRIC: "application/octet-stream",
    # The JSON answer's arrays as the columns of an Arrow IPC stream (service.outputs.arrow);
    # IANA's registration of the stream format.
    Output.ARROW: "application/vnd.apache.arrow.stream",
}
