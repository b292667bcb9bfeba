"""The sample meshes bundled with the package (real scans; credits in ``samples/SOURCES.md``)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

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
    """

    name: str
    description: str
    credit: str
    licence: str

    @property
    def path(self) -> Path:
        return FOLDER / self.name


_LEE_PERRY_SMITH = (
    '"Infinite, 3D Head Scan" by Lee Perry-Smith (Infinite-Realities, ir-ltd.net), based on a '
    "work at www.triplegangers.com; converted from the scan's three.js example copy."
)

SAMPLES: dict[str, Sample] = {
    sample.name: sample
    for sample in (
        Sample(
            "lee-perry-smith.glb",
            "3D scan of a bald human head with shoulders; Y up, face towards +Z; watertight",
            _LEE_PERRY_SMITH,
            "CC BY 3.0",
        ),
        Sample(
            "lee-perry-smith.obj",
            "the same head scan as OBJ",
            _LEE_PERRY_SMITH,
            "CC BY 3.0",
        ),
        Sample(
            "fsaverage-head.ply",
            "FreeSurfer fsaverage scalp surface (head with face, neck cut flat), millimetres, "
            "RAS axes; watertight and star-shaped from its bounding-box centre",
            "FreeSurfer's fsaverage subject, read from the mne Python package "
            "(mne/data/fsaverage/fsaverage-head.fif).",
            "BSD-3-Clause (mne); FreeSurfer licence (surface)",
        ),
        Sample(
            "nefertiti-lowres.obj",
            "remeshed 3D scan of the Nefertiti bust; the crown overhangs, so it is not "
            "star-shaped from any point",
            "Scan released by Nora Al-Badri and Jan Nikolai Nelles (2016); remesh from the "
            "odedstein/meshes collection.",
            "Public domain",
        ),
    )
}
