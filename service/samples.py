"""The sample meshes bundled with the package (real scans; credits in ``samples/SOURCES.md``)
and what ``/v1/samples`` says of them."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from pathlib import Path

from pydantic import Field

from .capabilities.fields import choice
from .capabilities.units import LengthUnit
from .encoding import Answer
from .meshio import format_of, read_mesh
from .settings import Settings

FOLDER = Path(__file__).with_name("samples")


@dataclass(frozen=True)
class Sample:
    """One bundled mesh file.

    Attributes
    ----------
    name : str, the file name (also its id in the API)
    description : str
    credit : str, the attribution its licence asks for
    licence : str
    units : LengthUnit, the file's length unit: the source's, or estimated from the size of
        what it shows (then ``description`` says so)
    """

    name: str
    description: str
    credit: str
    licence: str
    units: LengthUnit

    @property
    def path(self) -> Path:
        return FOLDER / self.name


_LEE_PERRY_SMITH = (
    '"Infinite, 3D Head Scan" by Lee Perry-Smith (Infinite-Realities, ir-ltd.net), based on a '
    "work at www.triplegangers.com; converted from the scan's three.js example copy."
)

#: The scan's file gives no unit: its unit is estimated from the head's width.
_LEE_PERRY_SMITH_UNITS = (
    "Units estimated (the file gives none): the head is 3.6 units wide where a head is about "
    "15 cm, so a unit is about 4 cm; cm is the nearest unit, with which lengths read about 4 "
    "times and areas about 18 times too small (a known distance gives true sizes)"
)

SAMPLES: dict[str, Sample] = {
    sample.name: sample
    for sample in (
        Sample(
            "lee-perry-smith.glb",
            "3D scan of a bald human head with shoulders; Y up, face towards +Z; watertight. "
            + _LEE_PERRY_SMITH_UNITS,
            _LEE_PERRY_SMITH,
            "CC BY 3.0",
            LengthUnit.CM,
        ),
        Sample(
            "lee-perry-smith.obj",
            "the same head scan as OBJ. " + _LEE_PERRY_SMITH_UNITS,
            _LEE_PERRY_SMITH,
            "CC BY 3.0",
            LengthUnit.CM,
        ),
        Sample(
            "fsaverage-head.ply",
            "FreeSurfer fsaverage scalp surface (head with face, neck cut flat), millimetres, "
            "RAS axes; watertight and star-shaped from its bounding-box centre",
            "FreeSurfer's fsaverage subject, read from the mne Python package "
            "(mne/data/fsaverage/fsaverage-head.fif).",
            "BSD-3-Clause (mne); FreeSurfer licence (surface)",
            LengthUnit.MM,
        ),
        Sample(
            "nefertiti-lowres.obj",
            "remeshed 3D scan of the Nefertiti bust; the crown overhangs, so it is not "
            "star-shaped from any point. Units estimated (the file gives none): the bust is "
            "495 units tall and the original 48 cm, so about 1 mm per unit",
            "Scan released by Nora Al-Badri and Jan Nikolai Nelles (2016); remesh from the "
            "odedstein/meshes collection.",
            "Public domain",
            LengthUnit.MM,
        ),
    )
}


class SampleInfo(Answer):
    name: str
    format: str
    vertices: int
    faces: int
    bytes: int
    description: str
    credit: str
    licence: str
    units: choice(LengthUnit) = Field(
        description="The file's length unit, to send as params.units: the source's, or "
        "estimated from the size of what it shows (then the description says so)."
    )
    url: str = Field(description="Where to download it.")


@cache
def _sample_info(name: str) -> SampleInfo:
    sample = SAMPLES[name]
    data = sample.path.read_bytes()
    # A bundled file is trusted: read with the default limits, whatever the service's are.
    mesh = read_mesh(data, format_of(name, None), Settings().limits)
    return SampleInfo(
        name=name,
        format=mesh.format,
        vertices=len(mesh.vertices),
        faces=len(mesh.faces),
        bytes=len(data),
        description=sample.description,
        credit=sample.credit,
        licence=sample.licence,
        units=sample.units,
        url=f"/v1/samples/{name}",
    )


def sample_infos() -> list[SampleInfo]:
    return [_sample_info(name) for name in SAMPLES]
