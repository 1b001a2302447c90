"""The excitations' rank counted alone (:func:`excitation_rank`, the time files' choice of a
point's only double hits) as the identification's geometry check counts it."""

from __future__ import annotations

import numpy as np
import pytest

from processing.geometry import check_geometry, excitation_rank

#: triaxial responses at four corners of a box
RESP_XYZ = np.repeat([[0.3, 0.2, 0.1], [-0.3, 0.2, 0.1], [0.3, -0.2, 0.2], [0.0, 0.0, -0.2]],
                     3, axis=0)
RESP_DIRS = np.tile(np.eye(3), (4, 1))


@pytest.mark.parametrize(("xyz", "dirs", "rank"), [
    # six independent forces
    ([[0.3, 0, 0], [0.3, 0, 0], [0, 0.2, 0], [0, 0.2, 0], [0, 0, 0.1], [-0.3, 0.1, 0]],
     [[0, 1, 0], [0, 0, 1], [1, 0, 0], [0, 0, 1], [1, 0, 0], [0, 1, 0]], 6),
    # all along one line of action, at two points on it: one force and no moment about it
    ([[0, 0, 0], [0.1, 0, 0], [0.2, 0, 0], [0.3, 0, 0], [0.4, 0, 0], [0.5, 0, 0]],
     [[1, 0, 0]] * 6, 1),
    # all vertical, at points in a plane: Fz, Mx, My
    ([[0.3, 0.2, 0], [-0.3, 0.2, 0], [0.3, -0.2, 0], [-0.3, -0.2, 0], [0, 0, 0], [0.1, 0, 0]],
     [[0, 0, 1]] * 6, 3),
    # five forces: five at most
    ([[0.3, 0, 0], [0.3, 0, 0], [0, 0.2, 0], [0, 0.2, 0], [0, 0, 0.1]],
     [[0, 1, 0], [0, 0, 1], [1, 0, 0], [0, 0, 1], [1, 0, 0]], 5),
])
def test_excitation_rank_is_the_geometry_checks(xyz: list, dirs: list, rank: int) -> None:
    assert excitation_rank(xyz, dirs) == rank
    assert check_geometry(RESP_XYZ, RESP_DIRS, xyz, dirs).rank_T == rank
