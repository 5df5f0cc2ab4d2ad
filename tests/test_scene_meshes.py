"""The meshes of the 3D views are closed and wound outwards: the viewer culls back
faces, so an inward winding would show the far inside of a part instead of its near side."""

import numpy as np
import pytest

from lab_modules.scenes.rotor import shaft_mesh, tube


def signed_volume(vertices, faces) -> float:
    """Divergence theorem: positive for a closed mesh whose faces point outwards."""
    a, b, c = (vertices[faces[:, k]].astype(float) for k in range(3))
    return float(np.sum(np.einsum("ij,ij->i", a, np.cross(b, c))) / 6.0)


@pytest.mark.parametrize("length_m, inner_m, outer_m, segments",
                         [(0.1, 0.136, 0.216, 96), (0.16, 0.0, 0.05, 32), (1.0, 0.5, 1.0, 16)])
def test_tube_is_closed_and_wound_outwards(length_m, inner_m, outer_m, segments):
    vertices, faces = tube(length_m, inner_m, outer_m, segments)
    polygon_area = 0.5 * segments * np.sin(2 * np.pi / segments)   # of a unit-radius regular polygon
    expected = length_m * polygon_area * (outer_m**2 - max(inner_m, 1e-6) ** 2)
    assert signed_volume(vertices, faces) == pytest.approx(expected, rel=1e-5)


def test_shaft_skin_faces_outwards():
    vertices, faces = shaft_mesh(np.linspace(0.0, 0.9, 10), 0.03)
    a, b, c = (vertices[faces[:, k]].astype(float) for k in range(3))
    normal, centre = np.cross(b - a, c - a), (a + b + c) / 3
    assert np.all(np.sum(normal[:, 1:] * centre[:, 1:], axis=1) > 0)
