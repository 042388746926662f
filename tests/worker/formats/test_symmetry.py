"""BOP symmetries of meshes with known symmetry groups: a cylinder (the soup can), a box with
three different sides, and a shape with none; in the form bop_toolkit's models_info holds."""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull

from worker.formats.symmetry import bop_symmetries, surface_moments
from worker.geometry.transforms import axis_angle_to_matrix

TURN = axis_angle_to_matrix(np.array([0.4, -0.3, 0.9]))
SHIFT = np.array([0.012, -0.02, 0.031])  # metres: the model's origin is not its centre


def _hull(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return points, ConvexHull(points).simplices


def _cylinder(radius: float = 0.033, height: float = 0.101, sides: int = 48
              ) -> tuple[np.ndarray, np.ndarray]:
    a = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    ring = np.stack([radius * np.cos(a), radius * np.sin(a)], axis=1)
    points = np.concatenate([np.column_stack([ring, np.full(sides, z)])
                             for z in (-height / 2, height / 2)])
    return _hull(points @ TURN.T + SHIFT)


def _box() -> tuple[np.ndarray, np.ndarray]:
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)],
                       dtype=np.float64) * (0.045, 0.03, 0.0175)
    return _hull(corners @ TURN.T + SHIFT)


def _transform(values: list[float]) -> tuple[np.ndarray, np.ndarray]:
    matrix = np.asarray(values, dtype=np.float64).reshape(4, 4)
    assert matrix[3].tolist() == [0.0, 0.0, 0.0, 1.0]
    return matrix[:3, :3], matrix[:3, 3]


class TestBopSymmetries:
    def test_a_cylinder_turns_freely_about_its_axis_and_flips_end_over_end(self) -> None:
        vertices, faces = _cylinder()
        result = bop_symmetries(vertices, faces)
        [continuous] = result["symmetries_continuous"]
        axis = np.asarray(continuous["axis"])
        assert abs(np.linalg.norm(axis) - 1) < 1e-6
        assert abs(abs(axis @ TURN[:, 2]) - 1) < 1e-6  # the can's own z axis, turned
        # The offset is a point on the axis in mm: the can's centre lies on that line.
        offset = np.asarray(continuous["offset"]) / 1000.0
        off_axis = (SHIFT - offset) - ((SHIFT - offset) @ axis) * axis
        assert np.linalg.norm(off_axis) < 1e-6
        flips = result["symmetries_discrete"]
        assert len(flips) == 2
        for values in flips:
            R, t_mm = _transform(values)
            assert np.allclose(R @ R.T, np.eye(3), atol=1e-5) and np.linalg.det(R) > 0
            assert np.allclose(R @ axis, -axis, atol=1e-5)  # end over end
            # A symmetry keeps the centre where it is: R c + t = c (mm).
            np.testing.assert_allclose(R @ (SHIFT * 1000) + t_mm, SHIFT * 1000, atol=1e-2)

    def test_a_box_with_three_different_sides_has_three_half_turns(self) -> None:
        vertices, faces = _box()
        result = bop_symmetries(vertices, faces)
        assert "symmetries_continuous" not in result
        found = [_transform(v) for v in result["symmetries_discrete"]]
        expected = [TURN @ np.diag(d) @ TURN.T for d in ((1, -1, -1), (-1, 1, -1), (-1, -1, 1))]
        assert len(found) == 3
        for R in expected:
            assert any(np.allclose(R, got, atol=1e-5) for got, _ in found)
        # Each maps every corner onto a corner (mm).
        corners = vertices * 1000
        for R, t in found:
            moved = corners @ R.T + t
            distance = np.linalg.norm(moved[:, None] - corners[None], axis=-1).min(axis=1)
            assert distance.max() < 1e-3

    def test_an_irregular_shape_has_no_symmetry(self) -> None:
        rng = np.random.default_rng(3)
        vertices, faces = _hull(rng.normal(scale=0.03, size=(12, 3)))
        assert bop_symmetries(vertices, faces) == {}

    def test_surface_moments_are_exact_for_a_unit_square(self) -> None:
        square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=np.float64)
        centre, second = surface_moments(square, np.array([[0, 1, 2], [0, 2, 3]]))
        np.testing.assert_allclose(centre, [0.5, 0.5, 0.0])
        # Mean of x^2 over the unit square is 1/3, of x y 1/4.
        np.testing.assert_allclose(second[:2, :2], [[1 / 3, 1 / 4], [1 / 4, 1 / 3]])
