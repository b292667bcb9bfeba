"""The 2D layouts and the metrics measured on them (transforms.layouts; docs/math.md,
section 7)."""

from __future__ import annotations

import numpy as np

from transforms import Chart, Frame, PoleCap, flatten_region

from .conftest import scalp


def test_mercator_layout_is_measured_as_returned():
    vertices, faces = scalp()
    frame = Frame.from_pole_up([0, 0, -1], [0, 1, 0], (vertices.min(0) + vertices.max(0)) / 2)
    chart = Chart.distorted(PoleCap.from_sigma(0.3))
    paper = flatten_region(vertices, faces, frame, chart)
    mercator = flatten_region(vertices, faces, frame, chart, layout="mercator")
    np.testing.assert_array_equal(mercator.x, mercator.phi)
    np.testing.assert_allclose(mercator.y, np.log(np.tan((np.pi - mercator.theta) / 2)))
    np.testing.assert_array_equal(paper.y, paper.theta)
    # Mercator keeps the sphere's angles: only the radial projection bends them.
    assert mercator.distortion.conformal.mean < paper.distortion.conformal.mean
    # The same triangles are flagged: validation reads the angles, not the layout.
    assert mercator.validation.folded_faces.tolist() == paper.validation.folded_faces.tolist()
