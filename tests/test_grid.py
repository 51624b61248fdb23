import numpy as np
import pytest

from ogm_ppl import Grid


def test_world_cell_round_trip_2d():
    g = Grid((4, 5), resolution=0.5, origin=(-1.0, 2.0))
    cells = np.array([[r, c] for r in range(4) for c in range(5)])
    centres = g.cell_to_world(cells)
    np.testing.assert_array_equal(g.world_to_cell(centres), cells)
    np.testing.assert_array_equal(g.flat_index(cells), np.arange(20))
    assert g.extent == (-1.0, 1.5, 2.0, 4.0)
    assert g.contains([[-1.0, 2.0], [1.49, 3.99]]).all()
    assert not g.contains([[1.5, 3.0], [0.0, 1.99]]).any()
    # a point outside the grid has a cell of its own, whose row-major index would name another cell (or none)
    with pytest.raises(ValueError, match=r"cell \(row 3, col -1\) lies off the 4 x 5 grid"):
        g.flat_index(g.world_to_cell([[-1.1, 3.9]]))
    with pytest.raises(ValueError, match=r"cell \(row -1, col 0\)"):
        g.flat_index([-1, 0])
    with pytest.raises(ValueError, match="cell 10 lies off the grid"):
        Grid.line(10).flat_index([3, 10])


def test_one_d_grid():
    g = Grid.line(10, resolution=0.1)
    assert g.ndim == 1 and g.rows == 1 and g.cols == 10 and g.num_cells == 10
    np.testing.assert_array_equal(g.world_to_cell([0.05, 0.95]), [0, 9])
    assert g.contains([0.0, 0.99]).all() and not g.contains([-0.01, 1.0]).any()


@pytest.mark.parametrize(
    "kwargs, field",
    [
        (dict(shape=(0, 3)), "shape"),
        (dict(shape=(2, 3, 4)), "shape"),
        (dict(shape=(3,), resolution=0.0), "resolution"),
        (dict(shape=(3,), resolution=float("nan")), "resolution"),
        (dict(shape=(3,), origin=(0.0, float("inf"))), "origin"),
    ],
)
def test_bad_grid(kwargs, field):
    with pytest.raises(ValueError, match=field):
        Grid(**kwargs)


@pytest.mark.parametrize("shape", [(20.5, 20), (20, float("nan")), (2.0000001,)])
def test_fractional_shape_refused(shape):
    """A fractional cell count is refused, not truncated (``Grid((20.5, 20))`` is not ``(20, 20)``)."""
    with pytest.raises(ValueError, match=r"shape\[\d\] must be a whole number"):
        Grid(shape)


@pytest.mark.parametrize("shape", [("20", 20), (True, 3), (None, 3)])
def test_non_numeric_shape_refused(shape):
    with pytest.raises(TypeError, match=r"shape\[\d\] must be an integer"):
        Grid(shape)


def test_integral_float_and_numpy_shapes_accepted():
    assert Grid((20.0, np.int64(3))).shape == (20, 3)
